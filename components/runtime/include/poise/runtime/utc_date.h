// The host's calendar date, for the magnetic model's default date (poise/core/north.h). It reads
// the wall clock, so it lives here in the host runtime, never in an estimator core.
#pragma once

#include <string>

namespace poise::runtime {

/// Today's date in UTC, YYYY-MM-DD.
std::string utc_today();

}  // namespace poise::runtime
