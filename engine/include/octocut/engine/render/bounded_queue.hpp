#pragma once
// A bounded queue between one producer and one worker thread, with backpressure and the worker's first failure
// handed back to the producer: what the frame writer and the render thread share.
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include "octocut/sim/timing.hpp"

namespace octocut::engine {

template <class T>
class BoundedQueue {
 public:
  explicit BoundedQueue(std::size_t capacity) : m_capacity(capacity == 0 ? 1 : capacity) {}

  /// Waits for room (unless the worker failed or the queue is closed), then queues `item`. Returns the time it
  /// waited, ms. Rethrows the worker's failure; throws std::logic_error after close() (`who` names the caller).
  double push(T item, const char* who) {
    std::unique_lock lock(m_mutex);
    const auto t0 = sim::Clock::now();
    m_not_full.wait(lock, [&] { return m_queue.size() < m_capacity || m_error || m_closed; });
    const double waited = sim::ms_since(t0);
    if (m_error) std::rethrow_exception(m_error);
    if (m_closed) throw std::logic_error(std::string(who) + "::push after finish");
    m_queue.push_back(std::move(item));
    m_not_empty.notify_one();
    return waited;
  }
  /// The worker's next item, oldest first, waiting for one; nothing once closed and drained, or after fail().
  std::optional<T> pop() {
    std::optional<T> out;
    {
      std::unique_lock lock(m_mutex);
      m_not_empty.wait(lock, [&] { return !m_queue.empty() || m_closed || m_error; });
      if (m_queue.empty() || m_error) return out;
      out = std::move(m_queue.front());
      m_queue.pop_front();
    }
    m_not_full.notify_one();
    return out;
  }
  /// No more items will come: the worker drains the queue, then pop() returns nothing.
  void close() {
    {
      std::lock_guard lock(m_mutex);
      m_closed = true;
    }
    m_not_empty.notify_all();
    m_not_full.notify_all();
  }
  /// The worker failed: keeps the first failure, drops what is queued and wakes the producer.
  void fail(std::exception_ptr error) {
    {
      std::lock_guard lock(m_mutex);
      if (!m_error) m_error = std::move(error);
      m_queue.clear();
    }
    m_not_full.notify_all();
    m_not_empty.notify_all();
  }
  /// The first failure, or null.
  [[nodiscard]] std::exception_ptr error() const {
    std::lock_guard lock(m_mutex);
    return m_error;
  }

 private:
  std::size_t m_capacity;
  mutable std::mutex m_mutex;
  std::condition_variable m_not_full, m_not_empty;
  std::deque<T> m_queue;  ///< items waiting for the worker (<= m_capacity)
  bool m_closed = false;  ///< no more items will come
  std::exception_ptr m_error;
};

}  // namespace octocut::engine
