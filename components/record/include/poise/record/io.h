// Byte sinks and sources behind the MCAP writer and reader, so tests can use memory buffers and
// inject failures (disk full) without touching the file system.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace poise::record {

/// A sink or source failed (I/O error, disk full, unsupported operation). `what()` names the file.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Where the writer puts bytes. Writes are whole records (or groups of records); a sink passes them
/// to the operating system at once (no user-space buffering), so a killed process loses nothing
/// that was written.
class Sink {
 public:
  virtual ~Sink() = default;
  /// Appends SIZE bytes at position(). Throws IoError on failure; then position() tells how far
  /// the sink got (bytes may have been partly written).
  virtual void write(const uint8_t* data, size_t size) = 0;
  /// Cuts the sink back to SIZE bytes (SIZE <= position()). Throws IoError if impossible.
  virtual void truncate(uint64_t size) = 0;
  /// Bytes written so far (after a failed write: what actually reached the sink).
  [[nodiscard]] virtual uint64_t position() const = 0;
  /// A name for messages ("'out.mcap'", "memory buffer").
  [[nodiscard]] virtual std::string name() const = 0;
};

/// A file written with POSIX write(2) (created/truncated on open). Throws IoError if it cannot be
/// opened.
std::unique_ptr<Sink> open_file_sink(const std::string& path);

/// Appends into BUFFER (which must outlive the sink).
class MemorySink : public Sink {
 public:
  explicit MemorySink(std::vector<uint8_t>& buffer) : buffer_(buffer) { buffer_.clear(); }
  void write(const uint8_t* data, size_t size) override {
    buffer_.insert(buffer_.end(), data, data + size);
  }
  void truncate(uint64_t size) override { buffer_.resize(static_cast<size_t>(size)); }
  [[nodiscard]] uint64_t position() const override { return buffer_.size(); }
  [[nodiscard]] std::string name() const override { return "memory buffer"; }

 private:
  std::vector<uint8_t>& buffer_;
};

/// Random-access bytes for the reader.
class Source {
 public:
  virtual ~Source() = default;
  [[nodiscard]] virtual uint64_t size() const = 0;
  /// Reads exactly SIZE bytes at OFFSET into OUT; throws IoError if they are not all there.
  virtual void read(uint64_t offset, size_t size, uint8_t* out) const = 0;
  [[nodiscard]] virtual std::string name() const = 0;
};

/// A regular file read with pread(2). Throws IoError if it cannot be opened or is not a regular
/// file (a FIFO, a device, a directory: refused at once, never waited on).
std::unique_ptr<Source> open_file_source(const std::string& path);

/// Throws IoError when OUTPUT names the same file as one of INPUTS (after symlinks and hard
/// links: same device and inode), so an output can never be opened over an input.
void refuse_output_over_input(const std::string& output, const std::vector<std::string>& inputs);

/// An output written under a temporary name beside PATH (PATH.partial-PID) and renamed onto PATH
/// by commit(): PATH is never truncated, and holds either what it held before or the whole new
/// file. Destroyed without commit(), the temporary file is removed. When PATH exists and is not a
/// regular file (a device such as /dev/null or /dev/full, a FIFO), it is written in place and
/// commit() renames nothing: renaming onto it would replace the device with a file (as root,
/// `-o /dev/null` used to turn the system's /dev/null into a regular file).
class ReplacingFile {
 public:
  explicit ReplacingFile(std::string path);
  ~ReplacingFile();
  ReplacingFile(const ReplacingFile&) = delete;
  ReplacingFile& operator=(const ReplacingFile&) = delete;
  /// The name to write to.
  [[nodiscard]] const std::string& temporary() const { return temporary_; }
  /// Renames the temporary file onto the path. Throws IoError if it cannot.
  void commit();

 private:
  std::string path_;
  std::string temporary_;
  bool committed_ = false;
};

/// Reads from a copy of BYTES.
class MemorySource : public Source {
 public:
  explicit MemorySource(std::vector<uint8_t> bytes) : bytes_(std::move(bytes)) {}
  [[nodiscard]] uint64_t size() const override { return bytes_.size(); }
  void read(uint64_t offset, size_t size, uint8_t* out) const override;
  [[nodiscard]] std::string name() const override { return "memory buffer"; }

 private:
  std::vector<uint8_t> bytes_;
};

/// CRC-32 (ISO-HDLC / zlib polynomial 0xEDB88320), as MCAP uses. Pass the previous result as CRC
/// to continue a running checksum (start with 0).
uint32_t crc32_update(uint32_t crc, const uint8_t* data, size_t size);

}  // namespace poise::record
