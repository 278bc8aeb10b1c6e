#include "poise/record/io.h"

#include <array>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <utility>

namespace poise::record {
namespace {

std::string errno_text(int err) { return std::string(std::strerror(err)); }

std::string file_kind(mode_t mode) {
  if (S_ISFIFO(mode)) {
    return "a FIFO";
  }
  if (S_ISCHR(mode)) {
    return "a character device";
  }
  if (S_ISBLK(mode)) {
    return "a block device";
  }
  if (S_ISSOCK(mode)) {
    return "a socket";
  }
  if (S_ISDIR(mode)) {
    return "a directory";
  }
  return "not a regular file";
}

class FileSink : public Sink {
 public:
  explicit FileSink(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) {
      throw IoError("cannot create '" + path + "': " + errno_text(errno) +
                    " (check the directory exists and is writable)");
    }
  }
  ~FileSink() override {
    if (fd_ >= 0) {
      ::close(fd_);
    }
  }
  FileSink(const FileSink&) = delete;
  FileSink& operator=(const FileSink&) = delete;

  void write(const uint8_t* data, size_t size) override {
    size_t done = 0;
    while (done < size) {
      const ssize_t n = ::write(fd_, data + done, size - done);
      if (n < 0) {
        if (errno == EINTR) {
          continue;
        }
        throw IoError("writing '" + path_ + "' failed at byte " + std::to_string(position_) +
                      ": " + errno_text(errno));
      }
      if (n == 0) {
        throw IoError("writing '" + path_ + "' failed at byte " + std::to_string(position_) +
                      ": the device accepted no more bytes");
      }
      done += static_cast<size_t>(n);
      position_ += static_cast<uint64_t>(n);
    }
  }
  void truncate(uint64_t size) override {
    if (::ftruncate(fd_, static_cast<off_t>(size)) != 0 ||
        ::lseek(fd_, static_cast<off_t>(size), SEEK_SET) < 0) {
      throw IoError("cannot truncate '" + path_ + "' to " + std::to_string(size) +
                    " bytes: " + errno_text(errno));
    }
    position_ = size;
  }
  [[nodiscard]] uint64_t position() const override { return position_; }
  [[nodiscard]] std::string name() const override { return "'" + path_ + "'"; }

 private:
  std::string path_;
  int fd_ = -1;
  uint64_t position_ = 0;
};

class FileSource : public Source {
 public:
  explicit FileSource(const std::string& path) : path_(path) {
    // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer forever; a
    // regular file ignores the flag, and anything else is refused below.
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd_ < 0) {
      throw IoError("cannot open '" + path + "': " + errno_text(errno));
    }
    struct stat st {};
    if (::fstat(fd_, &st) != 0) {
      const int err = errno;
      ::close(fd_);
      throw IoError("cannot stat '" + path + "': " + errno_text(err));
    }
    if (!S_ISREG(st.st_mode)) {
      ::close(fd_);
      throw IoError("'" + path + "' is not a regular file (" + file_kind(st.st_mode) +
                    "): an MCAP recording is read from a file");
    }
    size_ = static_cast<uint64_t>(st.st_size);
  }
  ~FileSource() override { ::close(fd_); }
  FileSource(const FileSource&) = delete;
  FileSource& operator=(const FileSource&) = delete;

  [[nodiscard]] uint64_t size() const override { return size_; }
  void read(uint64_t offset, size_t size, uint8_t* out) const override {
    size_t done = 0;
    while (done < size) {
      const ssize_t n = ::pread(fd_, out + done, size - done, static_cast<off_t>(offset + done));
      if (n < 0 && errno == EINTR) {
        continue;
      }
      if (n <= 0) {
        throw IoError("reading '" + path_ + "' at byte " + std::to_string(offset + done) +
                      " failed: " + (n < 0 ? errno_text(errno) : std::string("end of file")));
      }
      done += static_cast<size_t>(n);
    }
  }
  [[nodiscard]] std::string name() const override { return "'" + path_ + "'"; }

 private:
  std::string path_;
  int fd_ = -1;
  uint64_t size_ = 0;
};

std::array<uint32_t, 256> make_crc_table() {
  std::array<uint32_t, 256> table{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) {
      c = (c & 1u) != 0 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    }
    table[i] = c;
  }
  return table;
}

}  // namespace

std::unique_ptr<Sink> open_file_sink(const std::string& path) {
  return std::make_unique<FileSink>(path);
}

std::unique_ptr<Source> open_file_source(const std::string& path) {
  return std::make_unique<FileSource>(path);
}

void refuse_output_over_input(const std::string& output, const std::vector<std::string>& inputs) {
  struct stat out {};
  if (::stat(output.c_str(), &out) != 0) {
    return;  // does not exist yet (or cannot be reached: creating it says why)
  }
  for (const std::string& input : inputs) {
    struct stat in {};
    if (::stat(input.c_str(), &in) == 0 && in.st_dev == out.st_dev && in.st_ino == out.st_ino) {
      throw IoError("the output '" + output + "' is the input '" + input +
                    "' (the same file): writing it would destroy the recording; choose another output");
    }
  }
}

namespace {
/// PATH exists and is something other than a regular file (a device, a FIFO, a socket): written
/// in place, never renamed onto. A directory is left to the open, which names it.
bool written_in_place(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode);
}
}  // namespace

ReplacingFile::ReplacingFile(std::string path)
    : path_(std::move(path)),
      temporary_(written_in_place(path_) ? path_ : path_ + ".partial-" + std::to_string(::getpid())) {}

ReplacingFile::~ReplacingFile() {
  if (!committed_ && temporary_ != path_) {
    ::unlink(temporary_.c_str());
  }
}

void ReplacingFile::commit() {
  if (temporary_ == path_) {  // written in place
    committed_ = true;
    return;
  }
  if (::rename(temporary_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    ::unlink(temporary_.c_str());
    committed_ = true;
    throw IoError("cannot move '" + temporary_ + "' to '" + path_ + "': " + errno_text(err));
  }
  committed_ = true;
}

void MemorySource::read(uint64_t offset, size_t size, uint8_t* out) const {
  if (offset > bytes_.size() || size > bytes_.size() - offset) {
    throw IoError("reading memory buffer: bytes " + std::to_string(offset) + "+" +
                  std::to_string(size) + " are past its end (" + std::to_string(bytes_.size()) +
                  ")");
  }
  if (size == 0) {
    return;  // OUT may be the null data() of an empty buffer (memcpy needs valid pointers)
  }
  std::memcpy(out, bytes_.data() + offset, size);
}

uint32_t crc32_update(uint32_t crc, const uint8_t* data, size_t size) {
  static const std::array<uint32_t, 256> table = make_crc_table();
  uint32_t c = crc ^ 0xFFFFFFFFu;
  for (size_t i = 0; i < size; ++i) {
    c = table[(c ^ data[i]) & 0xFFu] ^ (c >> 8);
  }
  return c ^ 0xFFFFFFFFu;
}

}  // namespace poise::record
