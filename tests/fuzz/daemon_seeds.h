#pragma once
// Seeds for the daemon's fuzz targets, written by make_fuzz_corpus.

#include <string>

namespace lrfnet::fuzz {

// datagram_fuzz: valid datagrams of every kind (made by the tracker's encoder) and hostile
// variants (bad versions, NaNs, huge counts, truncations).
void WriteDatagramSeeds(const std::string& dir);
// recording_fuzz: small recordings and UDP captures, whole and damaged.
void WriteRecordingSeeds(const std::string& dir);
// auth_fuzz: datagrams sealed with its keys, damaged copies, unsigned datagrams.
void WriteAuthSeeds(const std::string& dir);
// calibration_yaml_fuzz: calibration.yaml files the writer made, older formats, damaged copies.
void WriteCalibrationYamlSeeds(const std::string& dir);
// config_fuzz: the printed configs, the shipped scenarios, key files, calibration histories, truth
// poses, damaged copies (config_seeds.cc; ordinary build only).
void WriteConfigSeeds(const std::string& dir);

}  // namespace lrfnet::fuzz
