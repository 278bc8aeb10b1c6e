#include "poise/imu/framer.h"

namespace poise::imu {
namespace {
bool blank(std::string_view s) {
  for (const char c : s) {
    if (c != ' ' && c != '\t' && c != '\r') return false;
  }
  return true;
}
}  // namespace

LineFramer::LineFramer() {
  line_.reserve(kMaxLineBytes + 2);
  text_.reserve(kMaxLineBytes + 2);
}

void LineFramer::end_text(FrameSink& sink) {
  if (text_bytes_ == 0) return;
  if (text_bytes_ <= kMaxLineBytes + 1 && !text_.empty() && text_.front() == '#') {
    std::string_view t(text_);
    if (!t.empty() && t.back() == '\r') t.remove_suffix(1);
    sink.on_info(t);
  } else if (!(text_bytes_ == text_.size() && blank(text_))) {
    sink.on_reject(RejectReason::kGarbage, text_bytes_);
  }
  text_.clear();
  text_bytes_ = 0;
}

void LineFramer::feed(const char* data, std::size_t size, FrameSink& sink) {
  for (std::size_t i = 0; i < size; ++i) {
    const char c = data[i];
    if (c == '$') {
      if (mode_ == Mode::kLine) {
        sink.on_reject(RejectReason::kTruncated, line_.size());
      } else if (mode_ == Mode::kText) {
        // A '#' message cut by '$' is noise too: it never ended with '\n'.
        if (text_bytes_ > 0 && !(text_bytes_ == text_.size() && blank(text_))) {
          sink.on_reject(RejectReason::kGarbage, text_bytes_);
        }
        text_.clear();
        text_bytes_ = 0;
      }
      mode_ = Mode::kLine;
      line_.clear();
      line_ += c;
      continue;
    }
    if (c == '\n') {
      switch (mode_) {
        case Mode::kLine:
          sink.on_line(line_);
          line_.clear();
          break;
        case Mode::kText:
          end_text(sink);
          break;
        case Mode::kDiscard:
          discard_bytes_ = 0;
          break;
      }
      mode_ = Mode::kText;
      continue;
    }
    switch (mode_) {
      case Mode::kLine:
        line_ += c;
        if (line_.size() > kMaxLineBytes + 1) {  // +1: a trailing '\r' is allowed
          sink.on_reject(RejectReason::kOverlong, line_.size());
          line_.clear();
          mode_ = Mode::kDiscard;
        }
        break;
      case Mode::kText:
        if (text_.size() <= kMaxLineBytes + 1) text_ += c;
        ++text_bytes_;
        break;
      case Mode::kDiscard:
        ++discard_bytes_;
        break;
    }
  }
}

void LineFramer::reset(FrameSink& sink) {
  if (mode_ == Mode::kLine && !line_.empty()) {
    sink.on_reject(RejectReason::kTruncated, line_.size());
  } else if (mode_ == Mode::kText && text_bytes_ > 0 &&
             !(text_bytes_ == text_.size() && blank(text_))) {
    sink.on_reject(RejectReason::kGarbage, text_bytes_);
  }
  line_.clear();
  text_.clear();
  text_bytes_ = 0;
  discard_bytes_ = 0;
  mode_ = Mode::kText;
}

}  // namespace poise::imu
