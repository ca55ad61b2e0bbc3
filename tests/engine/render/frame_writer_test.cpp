// The frame writer: PNG round trip, frames in order, backpressure of the bounded queue, and a failure mid-run that
// keeps the frames already written.
#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <future>
#include <mutex>
#include <random>

#include "octocut/engine/render/frame_writer.hpp"
#include "octocut/engine/io/io.hpp"
#include "common/temp_dir.hpp"

namespace octocut::engine {
namespace {

namespace fs = std::filesystem;

/// A deterministic pseudo-random image whose content depends on `seed`.
Image test_image(int width, int height, unsigned seed) {
  Image image;
  image.width = width;
  image.height = height;
  image.rgb.resize(std::size_t(3) * width * height);
  std::mt19937 rng(seed);
  for (std::size_t i = 0; i < image.rgb.size(); ++i)
    image.rgb[i] = std::uint8_t(i % 7 == 0 ? rng() : (i / 3 + seed) % 251);
  return image;
}

class FrameWriterTest : public octocut::test::TempDirTest {
 protected:
};

TEST_F(FrameWriterTest, PngRoundTripIsExact) {
  for (const bool sub : {false, true}) {
    const Image image = test_image(37, 23, 5);
    const Image back = decode_png(encode_png(image, 1, sub), "memory");
    EXPECT_EQ(back.width, 37);
    EXPECT_EQ(back.height, 23);
    EXPECT_EQ(back.rgb, image.rgb);
  }
  EXPECT_THROW(decode_png("not a png at all", "x.png"), std::runtime_error);
  EXPECT_THROW(encode_png(Image{}), std::runtime_error);
}

TEST_F(FrameWriterTest, FramesComeOutInOrderWithTheirContent) {
  std::vector<long> order;
  std::mutex mutex;
  {
    FrameWriter writer(m_dir, 3, [&](long index) {
      std::lock_guard lock(mutex);
      order.push_back(index);
    });
    for (long i = 0; i < 12; ++i) writer.push(i, test_image(16, 8, unsigned(i)));
    writer.finish();
    EXPECT_EQ(writer.written(), 12);
    EXPECT_EQ(writer.write_ms().size(), 12u);
  }
  // Written in push order, each file decodes to the image pushed under its number, and nothing else is left.
  std::vector<long> expected(12);
  for (long i = 0; i < 12; ++i) expected[std::size_t(i)] = i;
  EXPECT_EQ(order, expected);
  for (long i = 0; i < 12; ++i) {
    const fs::path path = frame_path(m_dir, i);
    EXPECT_EQ(decode_png(read_file(path), path.string()).rgb, test_image(16, 8, unsigned(i)).rgb) << path;
  }
  EXPECT_EQ(frame_path(m_dir, 7).filename(), "frame_000007.png");
  EXPECT_EQ(std::distance(fs::directory_iterator(m_dir), fs::directory_iterator()), 12);
}

TEST_F(FrameWriterTest, FullQueueBlocksThePusherUntilTheWriterCatchesUp) {
  // The writer thread stalls on frame 0 until released.
  std::mutex mutex;
  std::condition_variable cv;
  bool released = false;
  std::atomic<bool> stalled{false};
  FrameWriter writer(m_dir, 2, [&](long index) {
    if (index != 0) return;
    stalled = true;
    std::unique_lock lock(mutex);
    cv.wait(lock, [&] { return released; });
  });
  writer.push(0, test_image(8, 8, 0));
  while (!stalled) std::this_thread::yield();
  // Frame 0 is taken by the stalled thread; frames 1 and 2 fill the queue of 2.
  writer.push(1, test_image(8, 8, 1));
  writer.push(2, test_image(8, 8, 2));
  // Frame 3 must wait.
  auto blocked = std::async(std::launch::async, [&] { writer.push(3, test_image(8, 8, 3)); });
  EXPECT_EQ(blocked.wait_for(std::chrono::milliseconds(300)), std::future_status::timeout);
  EXPECT_EQ(writer.written(), 0);
  // Releasing the writer lets the push through; every frame is written, none dropped.
  {
    std::lock_guard lock(mutex);
    released = true;
  }
  cv.notify_all();
  EXPECT_EQ(blocked.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  blocked.get();
  writer.finish();
  EXPECT_EQ(writer.written(), 4);
  EXPECT_GT(writer.blocked_ms(), 200.0);
  for (long i = 0; i < 4; ++i) EXPECT_TRUE(fs::is_regular_file(frame_path(m_dir, i))) << i;
}

TEST_F(FrameWriterTest, FailureMidRunKeepsTheFramesWrittenSoFar) {
  // A directory squats on frame 5's name, so that renaming the finished file over it fails.
  fs::create_directories(frame_path(m_dir, 5) / "occupied");
  FrameWriter writer(m_dir, 2);
  std::string error;
  try {
    for (long i = 0; i < 40; ++i) writer.push(i, test_image(16, 8, unsigned(i)));
    writer.finish();
  } catch (const std::exception& e) {
    error = e.what();
  }
  // The error names the frame; later calls repeat it.
  EXPECT_NE(error.find("frame_000005.png"), std::string::npos) << error;
  EXPECT_THROW(writer.finish(), std::runtime_error);
  EXPECT_EQ(writer.written(), 5);
  // Frames 0-4 are complete and intact; no temporary file is left behind; nothing after the failure was written.
  for (long i = 0; i < 5; ++i) {
    const fs::path path = frame_path(m_dir, i);
    EXPECT_EQ(decode_png(read_file(path), path.string()).rgb, test_image(16, 8, unsigned(i)).rgb) << path;
  }
  for (const auto& entry : fs::directory_iterator(m_dir)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(name.find(".tmp"), std::string::npos) << name;
  }
  EXPECT_FALSE(fs::exists(frame_path(m_dir, 6)));
}

}  // namespace
}  // namespace octocut::engine
