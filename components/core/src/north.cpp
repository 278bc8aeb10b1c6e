#include "poise/core/north.h"

#include <sstream>
#include <stdexcept>

namespace poise {

NorthReference resolve_north(const NorthParams& p, const std::string& today) {
  NorthReference ref;
  const bool given = !std::isnan(p.declination_deg);
  if (given && p.has_location) {
    throw std::invalid_argument(
        "give either declination_deg or location (the declination is then computed), not both");
  }
  if (given) {
    if (!(std::abs(p.declination_deg) <= 180.0)) {
      throw std::invalid_argument("declination_deg must be in [-180, 180] (deg, east of true north)");
    }
    ref.true_north = true;
    ref.declination_rad = p.declination_deg * 3.14159265358979323846 / 180.0;
    ref.source = "configured";
    return ref;
  }
  if (!p.has_location) {
    return ref;
  }
  const GeomagneticModel loaded = p.model_file.empty() ? GeomagneticModel{} : GeomagneticModel::load(p.model_file);
  const GeomagneticModel& model = p.model_file.empty() ? GeomagneticModel::wmm2025() : loaded;
  const std::string date = p.date.empty() ? today : p.date;
  double year = 0.0;
  GeomagneticField f;
  try {
    year = decimal_year_from_date(date);
    f = model.field(p.location, year);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("location: ") + e.what());
  }
  if (f.horizontal_nt < kGeomagneticBlackoutHorizontalNt) {
    std::ostringstream os;
    os << "location: the horizontal field there is " << f.horizontal_nt
       << " nT (< 2000 nT, near a magnetic pole): the model's declination is unreliable and a "
          "magnetometer heading unusable; give declination_deg if you must";
    throw std::invalid_argument(os.str());
  }
  ref.true_north = true;
  ref.declination_rad = f.declination_deg * 3.14159265358979323846 / 180.0;
  if (p.seed_field) {
    ref.field_ut = f.total_nt * 1e-3;
    ref.dip_deg = f.inclination_deg;
  }
  std::ostringstream os;
  os << model.name() << " at " << p.location.lat_deg << ", " << p.location.lon_deg << ", "
     << p.location.alt_m << " m on " << date << ": declination " << f.declination_deg << " deg, dip "
     << f.inclination_deg << " deg, |B| " << f.total_nt * 1e-3 << " uT";
  ref.source = os.str();
  return ref;
}

}  // namespace poise
