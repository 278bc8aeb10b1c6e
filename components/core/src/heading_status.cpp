#include "poise/core/heading_status.h"

namespace poise {

const char* to_string(HeadingStatus status) {
  switch (status) {
    case HeadingStatus::kNoReference: return "no_reference";
    case HeadingStatus::kVerified: return "verified";
    case HeadingStatus::kUnverified: return "unverified";
  }
  return "unknown";
}

}  // namespace poise
