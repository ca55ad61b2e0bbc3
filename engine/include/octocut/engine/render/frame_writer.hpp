#pragma once
// The frame writer (SPEC §6): PNG frames written by a background thread so that encoding overlaps the simulation.
#include <cstdint>
#include <exception>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "octocut/engine/render/bounded_queue.hpp"
#include "octocut/engine/render/render_scene.hpp"

namespace octocut::engine {

/// Encodes an RGB8 image as PNG bytes (libpng). `level` is the zlib level (0-9; 1 is fast); `filter_sub` selects
/// the PNG "sub" filter for every row instead of no filtering. The defaults are the writer's: level 1 with no
/// filter was both the fastest and the smallest of none/sub/up/paeth and the RLE/Huffman strategies on rendered
/// 1280 × 720 frames (flat backgrounds). Throws std::runtime_error on a libpng error.
std::string encode_png(const Image& image, int level = 1, bool filter_sub = false);

/// Decodes PNG bytes into an RGB8 image (8-bit RGB or RGBA; alpha dropped). Throws std::runtime_error naming
/// `what` (e.g. the file) on malformed data.
Image decode_png(const std::string& bytes, const std::string& what);

/// `dir/frame_%06d.png` for frame `index`.
std::filesystem::path frame_path(const std::filesystem::path& dir, long index);

/// Writes frames as `dir/frame_%06d.png` on a background thread. The queue holds at most `capacity` frames: push()
/// blocks while it is full (backpressure) and never drops a frame. Each file is written atomically. The first
/// failure stops the writer; later pushes and finish() rethrow it, and every frame written before it stays on disk.
class FrameWriter {
 public:
  /// Called on the writer thread before each frame is encoded, with the frame's index. Tests use it to stall or
  /// observe the writer; an exception it throws fails the writer like a write error.
  using Hook = std::function<void(long index)>;

  /// Starts the writer thread; `dir` must exist. `capacity` >= 1 frames (0 is taken as 1).
  explicit FrameWriter(std::filesystem::path dir, std::size_t capacity = 4, Hook before_write = {});
  /// Finishes the frames still queued and joins the thread (errors are swallowed here; call finish() to see them).
  ~FrameWriter();
  FrameWriter(const FrameWriter&) = delete;
  FrameWriter& operator=(const FrameWriter&) = delete;

  /// Queues frame `index` (blocking while the queue is full). Throws the writer's first error, if any.
  void push(long index, Image image);
  /// Writes every queued frame, stops the thread and rethrows the first error, if any. Idempotent.
  void finish();

  /// Frames written so far.
  [[nodiscard]] long written() const;
  /// Time spent encoding and writing each frame so far, ms (one entry per written frame).
  [[nodiscard]] std::vector<double> write_ms() const;
  /// Time push() spent blocked on a full queue, summed, ms.
  [[nodiscard]] double blocked_ms() const;

 private:
  void run();

  struct Job {
    long index = 0;
    Image image;
  };
  std::filesystem::path m_dir;
  BoundedQueue<Job> m_queue;         ///< frames waiting to be written
  Hook m_before_write;
  mutable std::mutex m_mutex;        ///< guards what follows
  long m_written = 0;
  std::vector<double> m_write_ms;    ///< per written frame, ms
  double m_blocked_ms = 0.0;
  std::thread m_thread;
};

}  // namespace octocut::engine
