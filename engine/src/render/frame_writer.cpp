#include "octocut/engine/render/frame_writer.hpp"

#include <png.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "octocut/engine/io/io.hpp"
#include "octocut/sim/timing.hpp"

namespace octocut::engine {

namespace {

/// State shared with libpng's callbacks. libpng reports errors by longjmp, which must not cross C++ frames with
/// destructors: the message is stored here and the caller throws once setjmp returns.
struct PngContext {
  std::string error;
  std::string* out = nullptr;
  const std::string* in = nullptr;
  std::size_t in_offset = 0;
};

void png_on_error(png_structp png, png_const_charp message) {
  auto* context = static_cast<PngContext*>(png_get_error_ptr(png));
  context->error = message;
  png_longjmp(png, 1);
}

void png_on_warning(png_structp, png_const_charp) {}

void png_write_bytes(png_structp png, png_bytep data, png_size_t length) {
  auto* context = static_cast<PngContext*>(png_get_io_ptr(png));
  context->out->append(reinterpret_cast<const char*>(data), length);
}

void png_flush_nothing(png_structp) {}

void png_read_bytes(png_structp png, png_bytep data, png_size_t length) {
  auto* context = static_cast<PngContext*>(png_get_io_ptr(png));
  if (context->in_offset + length > context->in->size()) png_error(png, "unexpected end of data");
  std::memcpy(data, context->in->data() + context->in_offset, length);
  context->in_offset += length;
}

using sim::Clock;

}  // namespace

std::string encode_png(const Image& image, int level, bool filter_sub) {
  if (image.width <= 0 || image.height <= 0 || image.rgb.size() != std::size_t(3) * image.width * image.height)
    throw std::runtime_error("encode_png: the image is empty or its size does not match its pixels");
  std::string out;
  PngContext context;
  context.out = &out;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &context, png_on_error, png_on_warning);
  if (png == nullptr) throw std::runtime_error("encode_png: out of memory");
  png_infop info = png_create_info_struct(png);
  // No C++ object with a destructor may be created between setjmp and the libpng calls.
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw std::runtime_error("encode_png: libpng: " + context.error);
  }
  png_set_write_fn(png, &context, png_write_bytes, png_flush_nothing);
  png_set_IHDR(png, info, png_uint_32(image.width), png_uint_32(image.height), 8, PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(png, level);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, filter_sub ? PNG_FILTER_SUB : PNG_FILTER_NONE);
  png_write_info(png, info);
  for (int y = 0; y < image.height; ++y)
    png_write_row(png, const_cast<png_bytep>(image.rgb.data() + std::size_t(3) * image.width * y));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return out;
}

Image decode_png(const std::string& bytes, const std::string& what) {
  if (bytes.size() < 8 || png_sig_cmp(reinterpret_cast<png_const_bytep>(bytes.data()), 0, 8) != 0)
    throw std::runtime_error(what + ": not a PNG file");
  PngContext context;
  context.in = &bytes;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &context, png_on_error, png_on_warning);
  if (png == nullptr) throw std::runtime_error(what + ": out of memory");
  png_infop info = png_create_info_struct(png);
  Image image;
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw std::runtime_error(what + ": malformed PNG: " + context.error);
  }
  png_set_read_fn(png, &context, png_read_bytes);
  png_read_info(png, info);
  // Normalise to 8-bit RGB.
  png_set_expand(png);
  png_set_strip_16(png);
  png_set_strip_alpha(png);
  png_set_gray_to_rgb(png);
  png_read_update_info(png, info);
  image.width = int(png_get_image_width(png, info));
  image.height = int(png_get_image_height(png, info));
  if (png_get_rowbytes(png, info) != png_size_t(3) * image.width) png_error(png, "unexpected pixel format");
  image.rgb.resize(std::size_t(3) * image.width * image.height);
  for (int y = 0; y < image.height; ++y) png_read_row(png, image.rgb.data() + std::size_t(3) * image.width * y, nullptr);
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return image;
}

std::filesystem::path frame_path(const std::filesystem::path& dir, long index) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%06ld.png", index);
  return dir / name;
}

FrameWriter::FrameWriter(std::filesystem::path dir, std::size_t capacity, Hook before_write)
    : m_dir(std::move(dir)), m_queue(capacity), m_before_write(std::move(before_write)) {
  m_thread = std::thread([this] { run(); });
}

FrameWriter::~FrameWriter() {
  try {
    finish();
  } catch (...) {
    // The caller did not ask for the error; the frames written so far stay on disk.
  }
}

void FrameWriter::push(long index, Image image) {
  // Backpressure: wait for room, unless the writer has failed or stopped.
  const double waited = m_queue.push({index, std::move(image)}, "FrameWriter");
  std::lock_guard lock(m_mutex);
  m_blocked_ms += waited;
}

void FrameWriter::finish() {
  // Stop accepting frames and let the thread drain the queue.
  m_queue.close();
  if (m_thread.joinable()) m_thread.join();
  if (const std::exception_ptr error = m_queue.error()) std::rethrow_exception(error);
}

long FrameWriter::written() const {
  std::lock_guard lock(m_mutex);
  return m_written;
}

std::vector<double> FrameWriter::write_ms() const {
  std::lock_guard lock(m_mutex);
  return m_write_ms;
}

double FrameWriter::blocked_ms() const {
  std::lock_guard lock(m_mutex);
  return m_blocked_ms;
}

void FrameWriter::run() {
  for (;;) {
    // Take the oldest frame, or leave when stopped and drained.
    std::optional<Job> next = m_queue.pop();
    if (!next) return;
    Job& job = *next;

    // Encode and write atomically; the first failure ends the writer and drops the rest of the queue.
    try {
      if (m_before_write) m_before_write(job.index);
      const auto t0 = Clock::now();
      write_file_atomic(frame_path(m_dir, job.index), encode_png(job.image));
      const double ms = sim::ms_since(t0);
      std::lock_guard lock(m_mutex);
      ++m_written;
      m_write_ms.push_back(ms);
    } catch (const std::exception& e) {
      m_queue.fail(std::make_exception_ptr(
          std::runtime_error(frame_path(m_dir, job.index).string() + ": cannot write the frame: " + e.what())));
      return;
    }
  }
}

}  // namespace octocut::engine
