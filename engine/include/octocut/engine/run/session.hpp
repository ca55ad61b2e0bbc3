#pragma once
// Recorded interactive sessions (`octocut view --record`, `octocut run --replay`): every input of a viewer session
// with the step at which it took effect, so that a session replays headless and deterministically and becomes a
// regression test. The file is JSON with a schema version ("octocut.session/1"); see docs/scene-format.md.
//
// Timing: an event with `step` k took effect after the k-th step of its world and before the next (its `t` is the
// simulated time then, k * dt, for reading only). Events are in the order they took effect; a `reset` starts a new
// world, after which steps count from 0 again.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "octocut/engine/scene/scene.hpp"
#include "octocut/sim/pose.hpp"

namespace octocut::engine {

class World;

/// The schema version written and accepted.
inline constexpr const char* kSessionSchema = "octocut.session/1";

/// What one recorded input did.
enum class SessionEventKind {
  hold,      ///< the tool was taken in hand (World::hold_tool)
  pose,      ///< the tool in hand moved (World::set_tool_pose)
  cut,       ///< a cut now with that tool (World::cut_now)
  material,  ///< E, nu, damping or the element edited (World::set_material)
  pause,     ///< the simulation was paused (no effect on the simulation; kept for reading)
  resume,    ///< ... and resumed
  reset,     ///< the world was rebuilt from the scene
};

/// One recorded input.
struct SessionEvent {
  SessionEventKind kind = SessionEventKind::pose;
  long step = 0;       ///< steps taken by the world when it took effect
  double t = 0.0;      ///< simulated time then, s (informative; `step` decides)
  std::size_t tool = 0;  ///< hold, pose, cut: the tool's index in the scene
  sim::Pose pose;        ///< pose: tool coordinates to world
  Material material;     ///< material: the whole material after the edit (element empty in sessions recorded
                         ///< before it was: the object's element stays)
};

/// A recorded session.
struct Session {
  std::string scene_name;               ///< the scene's `name`
  std::string scene_fingerprint;        ///< FNV-1a 64 of the scene file's bytes, 16 hex digits
  std::vector<std::string> sets;        ///< the --set overrides the session ran with, in order
  long end_step = 0;                    ///< steps of the last world when the session ended
  std::vector<SessionEvent> events;     ///< in the order they took effect
};

/// FNV-1a 64 of the file at `path` as 16 hex digits. Throws std::runtime_error when it cannot be read.
std::string scene_fingerprint(const std::string& path);

/// The session as JSON text (doubles written to round-trip exactly).
std::string session_json(const Session& session);

/// Parses and validates a session file's text. Throws SceneError "<file>: <JSON pointer>: <what is wrong>" for
/// malformed JSON, another schema version, a missing or mistyped key, a non-rotation, a bad material or steps out
/// of order.
Session parse_session(const std::string& text, const std::string& file);

/// Throws SceneError "<file>: /scene/...: ..." when `session` was recorded for another scene than `scene` (name or
/// file contents differ), or names a tool the scene does not have.
void check_session_scene(const Session& session, const Scene& scene, const std::string& file);

/// Applies one event to `world` (pause and resume do nothing; reset is the caller's: it rebuilds the world).
/// Throws std::invalid_argument for a material outside the ranges.
void apply_session_event(World& world, const SessionEvent& event);

/// The events' kind names as written ("hold", "pose", ...).
const char* to_string(SessionEventKind kind);

}  // namespace octocut::engine
