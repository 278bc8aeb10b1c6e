// Magnetic field gate shared by the attitude filters that use a magnetometer for heading (the
// parallel KF's KF2 and the selective EKF's heading row): decides, per magnetometer sample, whether
// the field is the undisturbed Earth field the heading can trust.
//
// Reference: the field magnitude m (uT) and dip alpha (rad, the angle of the field below the
// horizontal; sin(alpha) = -up . m / |m|) are learnt over the first startup_s seconds of
// magnetometer samples (or configured). A sample is disturbed when | |s_M| - m | > norm_tol * m or
// |dip(s_M, up) - alpha| > dip_tol (up = the filter's own up axis in the body frame, not the raw
// accelerometer, so an external acceleration does not trip the dip test).
//   - The reference follows the accepted field with time constant reference_tau_s (over accepted
//     time, updated once per kFieldGateWindowS): a slow change (temperature, another part of a
//     building) is adopted, a fast one is gated.
//   - After reacquire_s of continuous rejection with a field that stayed stable (norm within
//     reacquire_tol, dip within dip_tol / 2 of its own 1 s low-pass) for reacquire_s, that field
//     becomes the reference (the sensor was moved into another field for good).
//   - After max_reject_s of continuous rejection the sample is used anyway ("forced"): the gyro-only
//     heading drift stays bounded in a field that changed for good but never looked stable.
//   - verify_s > 0: a reference learnt at start-up is provisional ("not verified") until the gate
//     has accepted the field against it for verify_s seconds: a start next to a magnet learns the
//     magnet's field, and nothing in the field tells that until it changes. While provisional, a
//     gated field that stays consistent (norm within reacquire_tol and dip within dip_tol / 2 of
//     their own 1 s low-pass, restarted whenever the field moves) replaces it ("relearnt") when
//     its magnitude is one the Earth's field can have (kEarthFieldMinUt..kEarthFieldMaxUt) and
//     either the reference's is not (it held for startup_s, as long as the start-up learnt the
//     first one from) or it has held longer than the reference was accepted; it must then itself
//     be accepted for verify_s. A configured
//     (or World Magnetic Model) reference is verified from the start. 0: a learnt reference is
//     verified when learnt (the behaviour before verify_s).
//   - A hard-iron offset removed (offset_removed): a reference learnt at start-up on fields with
//     the offset in (a magnet on the sensor at power-on) describes the field plus the offset and
//     gates the field without it. The start-up's moments give the reference the start-up would
//     have learnt without the offset. Over startup_s of the field with the offset removed, the
//     reference that fits its mean norm and dip better decides, if that one passes the gate: the
//     reference moves (and the heading restarts on the field) or stays. A move is undone when the
//     offset stops being removed. Evidence that the offset came later settles it
//     (offset_after_startup()): the field moved at rest, the offset stepped, or the hard-iron
//     estimate converged on no offset since the start-up.
// Times in seconds of sample time (the dt given to step), never per sample. A value type: its
// state is copied with the filter's state (VQF-style getState/setState, replays).
#pragma once

#include "poise/core/hard_iron.h"

#include <Eigen/Core>

#include <cmath>
#include <cstdint>

namespace poise {

class ParamCheck;

/// Length of the window over which accepted samples are summed before the reference follows, s.
inline constexpr double kFieldGateWindowS = 0.04;
/// The Earth's field magnitude at the surface lies within this range everywhere (the World
/// Magnetic Model's total intensity spans about 22-67 uT), with a margin for calibration, uT. A
/// field outside it is not the Earth's alone.
inline constexpr double kEarthFieldMinUt = 20.0;
inline constexpr double kEarthFieldMaxUt = 70.0;

struct FieldGateParams {
  bool enabled = true;                  ///< false: every sample accepted (learning still runs)
  double field_magnitude_ut = std::nan("");  ///< m, uT; NaN = learn at start-up
  double dip_deg = std::nan("");             ///< alpha, deg; NaN = learn at start-up
  double startup_s = 1.0;               ///< start-up window for learning m and alpha, s
  double norm_tol = 0.05;               ///< relative | |s_M| - m | / m above which s_M is gated (0 = no norm test)
  double dip_tol_deg = 10.0;            ///< |dip - alpha| above which s_M is gated, deg
  double reference_tau_s = 100.0;       ///< the reference follows the accepted field, s (0 = fixed)
  double reacquire_s = 20.0;            ///< adopt a stable new field after this long gated, s (0 = never)
  double reacquire_tol = 0.05;          ///< relative stability of the candidate field for adoption
  double max_reject_s = 60.0;           ///< use the field anyway after this long gated, s (0 = never)
  double verify_s = 0.0;                ///< a learnt reference is provisional until accepted this long, s (0 = verified when learnt)

  /// Throws std::invalid_argument naming the key `<prefix><name>` (as spelled in the YAML file of
  /// the filter that embeds the gate; `names` maps each field to its key).
  struct Keys {
    const char* field_magnitude_ut;
    const char* dip_deg;
    const char* startup_s;
    const char* norm_tol;
    const char* dip_tol_deg;
    const char* reference_tau_s;
    const char* reacquire_s;
    const char* reacquire_tol;
    const char* max_reject_s;
    const char* verify_s = "verify_s";
  };
  void validate(const ParamCheck& check, const Keys& keys) const;
};

/// What the gate decided for one magnetometer sample.
enum class FieldVerdict : uint8_t {
  kLearning,  ///< the reference is being learnt: use the sample (heading from the raw field)
  kAccepted,  ///< within the gate (or the gate is off)
  kGated,     ///< disturbed: do not use it for heading
  kForced,    ///< disturbed, but gated for max_reject_s already: use it anyway
  kRelearnt,  ///< the provisional reference was replaced by this consistent field, or moved by an
              ///< offset that was there at start-up (offset_removed): restart the heading on it
};

/// What offset_removed() decided about the start-up reference.
enum class OffsetJudgement : uint8_t {
  kNone,   ///< nothing to judge (no start-up reference, or already judged)
  kOpen,   ///< neither reference accepts this field: judged again on the next
  kKept,   ///< the learnt reference fits the field without the offset: the offset came later
  kMoved,  ///< the offset was there at start-up: the reference without it replaces the learnt one
};

struct FieldGate {
  // reference
  double m_ut = 0.0;        ///< reference magnitude, uT
  double dip_rad = 0.0;     ///< reference dip, rad
  bool learnt = false;      ///< m and alpha known (configured or learnt)
  bool verified = false;    ///< the reference is verified (configured, or accepted for verify_s)
  double consistent_s = 0.0;  ///< accepted time since the provisional reference was learnt, s
  // learning
  double learn_time_s = 0.0;
  double learn_norm_sum = 0.0;
  double learn_dip_sum = 0.0;
  int learn_n = 0;
  // the start-up field's moments, in the body frame of each sample (offset_removed): the mean of
  // s_M, of |s_M|^2, of up . s_M and of up (up unit)
  Eigen::Vector3d learn_field_sum = Eigen::Vector3d::Zero();
  double learn_field2_sum = 0.0;
  double learn_up_field_sum = 0.0;
  Eigen::Vector3d learn_up_sum = Eigen::Vector3d::Zero();
  /// the reference is the start-up's (not configured, not adopted since), no offset has been
  /// judged against it yet and the field has not moved at rest since: offset_removed() may move it
  bool startup_reference = false;
  bool moved_by_offset = false;  ///< offset_removed() moved it: the next step() says kRelearnt
  bool offset_moved = false;     ///< the reference is the one moved by the offset (undone when it goes)
  double learnt_m_ut = 0.0;      ///< the start-up's reference, restored when a move is undone
  double learnt_dip_rad = 0.0;
  // the field with the offset removed, summed over time while it is judged (offset_removed)
  double offset_span_s = 0.0;
  double offset_norm_sum = 0.0;     ///< uT s
  double offset_sin_dip_sum = 0.0;  ///< s
  // re-acquisition candidate
  double cand_norm = 0.0;
  double cand_dip = 0.0;
  double cand_stable_s = 0.0;
  double rejected_s = 0.0;  ///< continuous time gated, s
  // gate bounds on sin(dip), recomputed only when the reference dip changes
  double bounds_dip = std::nan("");
  double sin_lo = 0.0;
  double sin_hi = 0.0;
  // reference following window (sums over accepted samples)
  double window_s = 0.0;
  double accepted_s = 0.0;
  double norm_sum = 0.0;     ///< integral of |s_M| dt over accepted samples, uT s
  double sin_dip_sum = 0.0;  ///< integral of sin(dip) dt over accepted samples, s
  // counters
  uint64_t gated = 0;
  uint64_t forced = 0;
  uint64_t reacquired = 0;
  uint64_t relearnt = 0;    ///< provisional references replaced (kRelearnt)
  uint64_t offset_moves = 0;  ///< start-up references moved by an offset there at start-up (kRelearnt)
  /// every replacement of the reference (reacquired, relearnt, moved by an offset or moved back):
  /// what a filter's own state derived from the reference starts again on
  uint64_t reference_epoch = 0;
  // the last sample tested (reporting): |s_M| (NaN when not tested) and sin(dip)
  double last_norm_ut = std::nan("");
  double last_sin_dip = 0.0;

  /// Back to a new gate (the configured reference, if any).
  void reset(const FieldGateParams& p);
  /// One magnetometer sample `mag` (uT, body) with the filter's up axis `up` (body, any length > 0),
  /// dt_s after the previous sample (0 for the first). Learns, tests, follows the reference and
  /// re-acquires; returns what to do with the sample.
  FieldVerdict step(const FieldGateParams& p, const Eigen::Vector3d& mag, const Eigen::Vector3d& up,
                    double dt_s);
  /// The filter removes the body-fixed offset `offset_ut` (uT, body) from the fields it gives the
  /// gate (call on every sample while it does, dt_s after the previous one). `mag` is this
  /// sample's field with the offset removed, `up` the filter's up axis (body). Judges, on the
  /// field's mean norm and dip over startup_s (as the start-up learnt the reference), whether the
  /// offset was there at start-up: each hypothesis is scored by gate_ratio() against its
  /// reference (the learnt one: it came later; the one the start-up would have learnt without it:
  /// it was there). kMoved: "there" scores lower and passes the gate; the reference becomes that
  /// one and the next step() says kRelearnt (the heading restarts on the field). kKept: "later"
  /// scores no higher and passes. kOpen while the span is shorter than startup_s, or when neither
  /// passes (a new span starts: the field, or the offset's estimate, is off now). kNone when there
  /// is nothing to judge (not the start-up's reference, judged already, the field moved at rest
  /// since). Non-finite inputs: kOpen, nothing summed.
  OffsetJudgement offset_removed(const FieldGateParams& p, const Eigen::Vector3d& offset_ut, const Eigen::Vector3d& mag,
                                 const Eigen::Vector3d& up, double dt_s);
  /// The filter no longer removes an offset: a span being judged starts again when it does, and a
  /// reference moved by the offset goes back to the start-up's (judged again on the next offset).
  void offset_not_removed() {
    if (offset_span_s > 0.0 || offset_moved) {  // per sample without an offset: nothing to undo, mostly
      undo_offset();
    }
  }
  /// The gate's side of a filter's hard-iron estimate, on every reading after the estimate's
  /// update: `corrected` is the reading the filter goes on with (the offset removed when
  /// hi.applied()), `up` its up axis (body), dt_s since the last reading. The estimate's verdicts
  /// that the offset came later (it stepped, or it converged on no offset) end the start-up
  /// reference's judging (offset_after_startup); while the offset is removed, offset_removed()
  /// judges it; when not, offset_not_removed().
  void hard_iron_reading(const FieldGateParams& p, const HardIronEstimator& hi, const Eigen::Vector3d& corrected,
                         const Eigen::Vector3d& up, double dt_s) {
    if (startup_reference) {
      const HardIronReport& r = hi.report();
      if (r.step == HardIronStep::kStep || (r.converged && !r.present && r.step == HardIronStep::kUpdated)) {
        offset_after_startup();
      }
    }
    if (!hi.applied()) {
      offset_not_removed();
    } else if (startup_reference) {
      offset_removed(p, hi.offset_ut(), corrected, up, dt_s);
    }
  }
  /// Evidence that whatever offset the filter removes from now on came after the start-up (the
  /// field moved while the sensor was at rest, the hard-iron estimate stepped, or it converged on
  /// no offset): the start-up's reference is not judged any more.
  void offset_after_startup() {
    if (!offset_moved) {
      startup_reference = false;
    }
  }
  /// Advances the reference-following window by dt_s (call once per filter sample, magnetometer
  /// or not); the reference moves once per kFieldGateWindowS.
  void tick(const FieldGateParams& p, double dt_s);
  /// Gate ratios of the last tested sample: norm deviation / (norm_tol m) and dip deviation (in
  /// sin) / half the gate's width; |r| > 1 <=> outside. Zero when not tested.
  [[nodiscard]] double norm_ratio(const FieldGateParams& p) const;
  [[nodiscard]] double dip_ratio() const;

 private:
  void learn(const FieldGateParams& p, const Eigen::Vector3d& mag, const Eigen::Vector3d& up, double dt_s);
  /// How far `mag` (norm, body) with `sin_dip` lies from a reference (m, dip): the larger of the
  /// norm and dip deviations over their tolerances (<= 1: the gate passes it).
  [[nodiscard]] static double gate_ratio(const FieldGateParams& p, double norm, double sin_dip, double m, double dip);
  void follow(const FieldGateParams& p);
  void adopt_candidate();  ///< the candidate becomes the reference; rejection and candidate restart
  void replace_reference(double m, double dip);  ///< a new reference; rejection and candidate restart
  void undo_offset();  ///< offset_not_removed()'s work: the span restarts, a move is undone
};

/// A field that moves while the sensor is at rest (shared by the filters whose heading uses the
/// field gate). At rest the body does not turn, so neither does a world-fixed field with a
/// constant body-frame offset seen from a gyro-propagated (almost inertial) frame: what moves it
/// is a magnet attached or brought near. An offset across the horizontal field changes |m| only
/// at second order (10 uT across 15 uT: +1.1 uT of 44) but turns the heading a lot (34 deg), so
/// the gate's norm and dip tests pass it. Judged on the field in that frame low-passed (the rest
/// detector's time constant) against the field when the rest began, which follows with the
/// gate's reference_tau_s while the field has not moved (a temperature drift; a magnet's field is
/// never adopted, as the gate's reference follows only the accepted field). A value type (copied
/// with the filter's state).
struct FieldMovedAtRest {
  Eigen::Vector3d field_lp = Eigen::Vector3d::Constant(std::nan(""));  ///< low-passed field in the frame, uT
  /// the low-passed field when the rest began (NaN: not at rest and nothing held), following with
  /// reference_tau_s while the field has not moved, uT
  Eigen::Vector3d rest_field = Eigen::Vector3d::Constant(std::nan(""));
  bool held = false;  ///< the field moved at rest and is still refused (hold())

  /// The rest's field forgotten, unless the field is held (hold()): in the motion after the rest
  /// it is what the field must come back to.
  void clear() {
    if (!held) {
      rest_field.setConstant(std::nan(""));
    }
  }
  /// Not judged (no reference, no rest detector): nothing held, the rest's field forgotten.
  void reset() {
    held = false;
    clear();
  }
  /// One sample: `field_i` the raw reading turned into the frame (R_ib m, uT), `at_rest` the rest
  /// detector's verdict, dt_s since the last; `lowpass_tau_s` the rest detector's time constant,
  /// `reference_tau_s` the gate's (0 = fixed), `tol_ut` the gate's norm tolerance (norm_tol m).
  /// True when the field has moved by more than tol_ut since the rest began.
  bool step(const Eigen::Vector3d& field_i, bool at_rest, double dt_s, double lowpass_tau_s, double reference_tau_s,
            double tol_ut);
  /// A field that moved at rest stays refused in the motion after it until the hard-iron estimate
  /// has judged it (`judged`: HardIronReport::judged()) or the field seen from the frame is back
  /// within tol_ut of the rest's field before it moved (the source has gone: a magnet fixed to the
  /// body turns with it and stays |b| > tol_ut away; a magnet fixed in the world is left behind).
  /// The motion's first seconds are when the raw field would pull the heading: the estimate needs
  /// rotation to tell the offset from the Earth's field, and the gate cannot. While held the
  /// rest's field is kept (step() does not forget it). `moved` is this sample's step();
  /// `at_rest` true (also for a filter without the estimate) gives `moved` itself. Returns
  /// whether the field is refused.
  bool hold(bool moved, bool at_rest, bool judged, double tol_ut);
};

}  // namespace poise
