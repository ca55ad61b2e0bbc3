// Recorded sessions without a window: `octocut run --replay` applies each input at the step it was recorded at and
// is deterministic; bad session files and sessions of another scene are bad input (exit 2, file and JSON pointer).
// The viewer that records sessions is tested under Xvfb in cli_view_test.cpp.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "common/report_util.hpp"
#include "common/cli_util.hpp"
#include "common/temp_dir.hpp"
#include "octocut/engine/run/session.hpp"
#include "octocut/engine/run/tool.hpp"
#include "octocut/engine/scene/scene_loader.hpp"
#include "octocut/sim/pose.hpp"

namespace {

namespace fs = std::filesystem;
using octocut::test::read_json;
using nlohmann::json;
using namespace octocut;
using test::CommandResult;
using test::run_octocut;

// The report without its timing keys.
std::string without_timings(const json& report) { return test::report_without_timings(report); }

class CliSessionTest : public test::TempDirTest {
 protected:
  // The meniscus punch scene without drawing and without contact, its paths absolute, copied into the test folder.
  fs::path meniscus(const std::string& element = "") const {
    json scene = read_json(std::string(OCTOCUT_SOURCE_DIR) + "/assets/scenes/meniscus_punch.json");
    if (!element.empty()) scene["object"]["material"]["element"] = element;
    const std::string meshes = std::string(OCTOCUT_SOURCE_DIR) + "/assets/meshes/";
    scene.erase("expected");
    scene["object"]["surface"] = meshes + "meniscus_10k.ply";
    scene["tools"][0]["mesh"] = meshes + "punch.ply";
    scene["render"]["enabled"] = false;
    scene["render"]["props"] = json::array();
    scene["tools"][0]["collide"] = false;  // the punch cuts where it is put, without pushing the rim away first
    return write("meniscus" + element + ".json", scene.dump(1));
  }

  // A session by hand: the punch taken in hand, moved to where the scene's first cut punches, a cut at step 5, the
  // material stiffened at step 6, and the end at step 12.
  engine::Session session(const fs::path& scene_file) const {
    const engine::Scene scene = engine::load_scene(scene_file.string());
    engine::Session s;
    s.scene_name = scene.name;
    s.scene_fingerprint = engine::scene_fingerprint(scene_file.string());
    const double dt = scene.solver.dt;
    engine::SessionEvent hold{engine::SessionEventKind::hold, 0, 0.0, 0, {}, {}};
    engine::SessionEvent pose{engine::SessionEventKind::pose, 3, 3 * dt, 0, engine::tool_pose(scene.tools[0], 0.7), {}};
    engine::SessionEvent cut{engine::SessionEventKind::cut, 5, 5 * dt, 0, {}, {}};
    engine::Material stiffer = scene.object.material;
    stiffer.young_modulus *= 2.0;
    engine::SessionEvent material{engine::SessionEventKind::material, 6, 6 * dt, 0, {}, stiffer};
    s.events = {hold, pose, cut, material};
    s.end_step = 12;
    return s;
  }
};

TEST_F(CliSessionTest, ReplayCutsAtTheRecordedStepAndIsDeterministic) {
  const fs::path scene = meniscus();
  const fs::path file = write("s.json", engine::session_json(session(scene)));
  auto replay = [&](const std::string& out) {
    const CommandResult r = run_octocut("run '" + scene.string() + "' --replay '" + file.string() +
                                        "' --no-render --quiet --out '" + (m_dir / out).string() + "'");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return read_json(m_dir / out / "report.json");
  };
  const json a = replay("a");
  // The held tool's six timeline cuts are gone; the one cut by hand ran after step 5, at t = 5 dt.
  ASSERT_EQ(a["cuts"].size(), 1u) << a["cuts"].dump();
  EXPECT_EQ(a["steps"].get<long>(), 12);
  EXPECT_NEAR(a["cuts"][0]["t"].get<double>(), 5 * 0.002, 1e-12);
  EXPECT_EQ(a["cuts"][0]["status"], "ok");
  EXPECT_EQ(a["cuts"][0]["scheduled"], false);
  // The scene's own first punch, at the same pose 0.7 s into its timeline, removes 3.05e-9 m^3 (its expected
  // block); here the tissue has barely begun to sag, so the same punch removes about as much.
  EXPECT_NEAR(a["cuts"][0]["removed_volume_m3"].get<double>(), 3.05e-9, 0.3e-9);
  EXPECT_EQ(a["surface"]["closed"], true);
  // The same session again: the same report apart from timings.
  EXPECT_EQ(without_timings(a), without_timings(replay("b")));
}

TEST_F(CliSessionTest, AResetStartsANewWorldAndTheStepsCountFromZero) {
  // The viewer's reset: the cut before it is gone with its world; the session's last world cuts at its own step 2.
  const fs::path scene = meniscus();
  engine::Session s = session(scene);
  s.events.pop_back();  // no material edit
  const engine::Scene loaded = engine::load_scene(scene.string());
  const double dt = loaded.solver.dt;
  const sim::Pose pose = engine::tool_pose(loaded.tools[0], 0.7);
  s.events.push_back({engine::SessionEventKind::reset, 8, 8 * dt, 0, {}, {}});
  s.events.push_back({engine::SessionEventKind::hold, 0, 0.0, 0, {}, {}});
  s.events.push_back({engine::SessionEventKind::pose, 0, 0.0, 0, pose, {}});
  s.events.push_back({engine::SessionEventKind::cut, 2, 2 * dt, 0, {}, {}});
  s.end_step = 4;
  const fs::path file = write("reset.json", engine::session_json(s));
  const CommandResult r = run_octocut("run '" + scene.string() + "' --replay '" + file.string() +
                                      "' --no-render --quiet --out '" + (m_dir / "o").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json report = read_json(m_dir / "o" / "report.json");
  EXPECT_EQ(report["steps"].get<long>(), 4);
  ASSERT_EQ(report["cuts"].size(), 1u) << report["cuts"].dump();
  EXPECT_NEAR(report["cuts"][0]["t"].get<double>(), 2 * dt, 1e-12);
  EXPECT_EQ(report["cuts"][0]["status"], "ok");
}

TEST_F(CliSessionTest, MaterialEditChangesTheMotion) {
  // The same session with and without the stiffening at step 6: the probes move differently afterwards.
  const fs::path scene = meniscus();
  engine::Session with = session(scene), without = with;
  without.events.pop_back();
  write("with.json", engine::session_json(with));
  write("without.json", engine::session_json(without));
  auto probe = [&](const std::string& name) {
    const CommandResult r = run_octocut("run '" + scene.string() + "' --replay '" + (m_dir / (name + ".json")).string() +
                                        "' --no-render --quiet --out '" + (m_dir / name).string() + "'");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return read_json(m_dir / name / "report.json")["probes"]["body_periphery"]["displacement"][2].get<double>();
  };
  EXPECT_NE(probe("with"), probe("without"));
}

TEST_F(CliSessionTest, MaterialEditsCarryTheElementAndSessionsWithoutItKeepTheObjects) {
  // The scene with trilinear hexahedra (not the default). The edit at step 6 is recorded with the element; a session
  // written before edits recorded it (no "element" key) replays with the object's element unchanged, exactly as the
  // same edit naming it; an edit to B-bar moves the tissue differently.
  const fs::path scene = meniscus("trilinear");
  const json recorded = json::parse(engine::session_json(session(scene)));
  ASSERT_EQ(recorded["events"][3]["material"]["element"], "trilinear");
  json old_format = recorded, bbar = recorded;
  old_format["events"][3]["material"].erase("element");
  bbar["events"][3]["material"]["element"] = "bbar";
  auto report = [&](const std::string& name, const json& session) {
    const fs::path file = write(name + ".json", session.dump(1));
    const CommandResult r = run_octocut("run '" + scene.string() + "' --replay '" + file.string() +
                                        "' --no-render --quiet --out '" + (m_dir / name).string() + "'");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return read_json(m_dir / name / "report.json");
  };
  const json a = report("recorded", recorded), b = report("old_format", old_format), c = report("bbar", bbar);
  EXPECT_EQ(without_timings(a), without_timings(b));
  EXPECT_NE(a["probes"]["body_periphery"]["displacement"], c["probes"]["body_periphery"]["displacement"]);
}

TEST_F(CliSessionTest, BadSessionFilesExitTwoNamingTheFileAndPointer) {
  const fs::path scene = meniscus();
  json good = json::parse(engine::session_json(session(scene)));
  struct Case {
    std::string name;
    std::string text;
    std::string expected;  // in the message, after the file name
  };
  json schema = good, rotation = good, kind = good, order = good, missing = good, element = good;
  schema["schema"] = "octocut.session/99";
  rotation["events"][1]["pose"]["rotation"][0] = {2.0, 0.0, 0.0};
  kind["events"][2]["kind"] = "teleport";
  order["events"][2]["step"] = 1;
  missing["events"][3].erase("material");
  element["events"][3]["material"]["element"] = "q8";
  const std::vector<Case> cases = {
      {"notjson", "{\"schema\": ", ": /: not JSON"},
      {"schema", schema.dump(), ": /schema: "},
      {"rotation", rotation.dump(), ": /events/1/pose/rotation: not a proper rotation"},
      {"kind", kind.dump(), ": /events/2/kind: unknown event kind 'teleport'"},
      {"order", order.dump(), ": /events/2/step: steps go back"},
      {"missing", missing.dump(), ": /events/3/material: missing"},
      {"element", element.dump(), ": /events/3/material/element: must be \"bbar\" or \"trilinear\""},
  };
  for (const Case& c : cases) {
    const fs::path file = write(c.name + ".json", c.text);
    const CommandResult r = run_octocut("run '" + scene.string() + "' --replay '" + file.string() + "' --no-render --quiet --out '" +
                                        (m_dir / "o").string() + "'");
    EXPECT_EQ(r.exit_code, 2) << c.name << ": " << r.output;
    EXPECT_NE(r.output.find(file.string() + c.expected), std::string::npos) << c.name << ": " << r.output;
    EXPECT_FALSE(fs::exists(m_dir / "o" / "report.json")) << c.name;
  }
  const CommandResult absent = run_octocut("run '" + scene.string() + "' --replay '" + (m_dir / "absent.json").string() +
                                           "' --no-render --quiet --out '" + (m_dir / "o").string() + "'");
  EXPECT_EQ(absent.exit_code, 2) << absent.output;
  EXPECT_NE(absent.output.find("absent.json: cannot read the session file"), std::string::npos) << absent.output;
}

TEST_F(CliSessionTest, SessionOfAnotherSceneExitsTwo) {
  const fs::path scene = meniscus();
  const engine::Session s = session(scene);
  // Another scene's name.
  engine::Session renamed = s;
  renamed.scene_name = "knee_arthroscopy";
  const fs::path other = write("other.json", engine::session_json(renamed));
  CommandResult r = run_octocut("run '" + scene.string() + "' --replay '" + other.string() + "' --no-render --quiet --out '" +
                                (m_dir / "o").string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find(other.string() + ": /scene/name: recorded for scene 'knee_arthroscopy'"), std::string::npos)
      << r.output;
  // The same name, but the scene file changed since the recording.
  const fs::path file = write("s.json", engine::session_json(s));
  json edited = read_json(scene);
  edited["duration"] = 2.0;
  std::ofstream(scene) << edited.dump(1);
  r = run_octocut("run '" + scene.string() + "' --replay '" + file.string() + "' --no-render --quiet --out '" +
                  (m_dir / "o").string() + "'");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find(file.string() + ": /scene/fingerprint: recorded for another version"), std::string::npos)
      << r.output;
}

}  // namespace
