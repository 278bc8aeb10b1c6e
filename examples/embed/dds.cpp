// A program that uses the installed DDS side of poise (poise::dds, poise::idl; Debian
// poise-dds-dev): it converts an IMU sample to the wire type and back, opens a participant with
// poise's loopback profile on domain 231 (nothing else listens there) and prints "ok dds" when the
// round trip is exact and the participant exists.
#include <poise/dds/convert.h>
#include <poise/dds/participant.h>

#include <cstdio>
#include <exception>

int main() {
  try {
    poise::ImuSample in;
    in.stamp_ns = 1'000'000'000;
    in.gyro_rps = Eigen::Vector3d(0.1, -0.2, 0.3);
    in.accel_mps2 = Eigen::Vector3d(0.0, 0.0, 9.81);
    const poise::ImuSample out = poise::dds::from_msg(poise::dds::to_msg(in, "embed"));
    const bool same = out.stamp_ns == in.stamp_ns && out.gyro_rps == in.gyro_rps &&
                      out.accel_mps2 == in.accel_mps2;
    poise::dds::ParticipantOptions options;
    options.domain = 231;
    options.profile = "poise_loopback";
    options.name = "poise_embed_dds";
    const poise::dds::Participant participant(options);
    std::printf("%s dds (IMU sample round trip %s, participant %s)\n", same ? "ok" : "FAILED",
                same ? "exact" : "changed", participant.get() != nullptr ? "created" : "missing");
    return same && participant.get() != nullptr ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "poise_embed_dds: %s\n", e.what());
    return 1;
  }
}
