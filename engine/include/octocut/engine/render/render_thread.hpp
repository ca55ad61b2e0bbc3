#pragma once
// The render thread (issue 20, item 4): `octocut run` hands each frame to it as a RenderScene snapshot, so that
// drawing overlaps the simulation. The thread owns its renderer (an EGL/GL context is current on one thread only, so
// the renderer is made, used and destroyed there), draws the snapshots in the order they were pushed, and hands each
// image to a sink (the frame writer). GL-free: any Renderer will do.
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "octocut/engine/render/bounded_queue.hpp"
#include "octocut/engine/render/render_scene.hpp"
#include "octocut/engine/render/renderer.hpp"

namespace octocut::engine {

/// Draws RenderScene snapshots on a thread of its own. The queue holds at most `capacity` snapshots: push() blocks
/// while it is full (backpressure; no frame is ever dropped) and measures the wait. The first failure (of the
/// renderer or of the sink) stops the thread: the snapshots still queued are dropped, later pushes and finish()
/// rethrow it, and every image handed to the sink before it stays handed.
class RenderThread {
 public:
  /// Makes the renderer; called once, on the render thread.
  using Factory = std::function<std::unique_ptr<Renderer>()>;
  /// Takes frame `index`'s image, on the render thread, in frame order (0, 1, 2, ...). May block (backpressure of
  /// the frame writer); an exception it throws fails the thread like a render error.
  using Sink = std::function<void(long index, Image image)>;

  /// Starts the thread and waits until it has made its renderer: a failure to make it (e.g. RenderError from EGL) is
  /// rethrown here, with the thread already joined. `capacity` >= 1 snapshots (0 is taken as 1). `sink` may be empty
  /// (frames rendered, not kept).
  RenderThread(Factory make, Sink sink, std::size_t capacity = 2);
  /// Finishes the queued frames and joins the thread (errors are swallowed here; call finish() to see them).
  ~RenderThread();
  RenderThread(const RenderThread&) = delete;
  RenderThread& operator=(const RenderThread&) = delete;

  /// Queues the next frame's snapshot (blocking while the queue is full). Throws the thread's first error, if any.
  void push(RenderScene scene);
  /// Draws every queued frame, stops and joins the thread (which destroys its renderer), and rethrows the first
  /// error, if any. Idempotent.
  void finish();

  /// Time each drawn frame took on the render thread (Renderer::render: draw and read-back), ms, in frame order.
  [[nodiscard]] std::vector<double> render_ms() const;
  /// The last entry of render_ms(), or 0 before the first frame.
  [[nodiscard]] double last_render_ms() const;
  /// Time each push() spent blocked on a full queue, ms, one entry per push.
  [[nodiscard]] std::vector<double> wait_ms() const;
  /// The renderer's description (Renderer::description()).
  [[nodiscard]] std::string description() const;

 private:
  void run(Factory make);

  Sink m_sink;
  BoundedQueue<RenderScene> m_queue;  ///< snapshots waiting to be drawn
  mutable std::mutex m_mutex;         ///< guards what follows
  std::condition_variable m_started_cv;
  bool m_started = false;           ///< the renderer was made, or making it failed
  std::exception_ptr m_start_error; ///< why making it failed
  std::vector<double> m_render_ms;  ///< per drawn frame, ms
  std::vector<double> m_wait_ms;    ///< per push, ms
  std::string m_description;
  std::thread m_thread;
};

}  // namespace octocut::engine
