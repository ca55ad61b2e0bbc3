#include "octocut/engine/render/render_thread.hpp"

#include <optional>
#include <utility>

#include "octocut/sim/timing.hpp"

namespace octocut::engine {

RenderThread::RenderThread(Factory make, Sink sink, std::size_t capacity)
    : m_sink(std::move(sink)), m_queue(capacity) {
  m_thread = std::thread([this, make = std::move(make)]() mutable { run(std::move(make)); });
  // The renderer is made on the thread: wait for it, so that a failure to start is the caller's, before any frame.
  std::unique_lock lock(m_mutex);
  m_started_cv.wait(lock, [&] { return m_started; });
  if (m_start_error) {
    const std::exception_ptr error = m_start_error;
    lock.unlock();
    m_thread.join();
    std::rethrow_exception(error);
  }
}

RenderThread::~RenderThread() {
  try {
    finish();
  } catch (...) {
    // The caller did not ask for the error; the frames handed to the sink so far stay handed.
  }
}

void RenderThread::push(RenderScene scene) {
  // Backpressure: wait for room, unless the thread has failed or stopped.
  const double waited = m_queue.push(std::move(scene), "RenderThread");
  std::lock_guard lock(m_mutex);
  m_wait_ms.push_back(waited);
}

void RenderThread::finish() {
  m_queue.close();
  if (m_thread.joinable()) m_thread.join();
  if (const std::exception_ptr error = m_queue.error()) std::rethrow_exception(error);
}

std::vector<double> RenderThread::render_ms() const {
  std::lock_guard lock(m_mutex);
  return m_render_ms;
}

double RenderThread::last_render_ms() const {
  std::lock_guard lock(m_mutex);
  return m_render_ms.empty() ? 0.0 : m_render_ms.back();
}

std::vector<double> RenderThread::wait_ms() const {
  std::lock_guard lock(m_mutex);
  return m_wait_ms;
}

std::string RenderThread::description() const {
  std::lock_guard lock(m_mutex);
  return m_description;
}

void RenderThread::run(Factory make) {
  // The renderer lives and dies on this thread: its GL context is current here only.
  std::unique_ptr<Renderer> renderer;
  try {
    renderer = make();
    const std::string description = renderer->description();
    std::lock_guard lock(m_mutex);
    m_description = description;
    m_started = true;
  } catch (...) {
    std::lock_guard lock(m_mutex);
    m_start_error = std::current_exception();
    m_started = true;
  }
  m_started_cv.notify_all();
  if (!renderer) return;

  for (long index = 0;; ++index) {
    // The oldest snapshot, or leave when stopped and drained.
    std::optional<RenderScene> next = m_queue.pop();
    if (!next) return;
    const RenderScene scene = std::move(*next);
    // Draw, then hand the image on; the first failure ends the thread and drops the rest of the queue.
    try {
      const auto t0 = sim::Clock::now();
      Image image = renderer->render(scene);
      const double ms = sim::ms_since(t0);
      {
        std::lock_guard lock(m_mutex);
        m_render_ms.push_back(ms);
      }
      if (m_sink) m_sink(index, std::move(image));
    } catch (...) {
      m_queue.fail(std::current_exception());
      return;
    }
  }
}

}  // namespace octocut::engine
