#pragma once
// The calibration report: a folder a person opens to judge a calibration.
//
//   calibration.svg / .png  the world (= reference sensor) frame: every calibrated sensor as a
//                           marker with its id and heading, its field of view as a translucent
//                           wedge, its background scan and its tracks transformed into the world
//                           (one colour per sensor), truth poses as grey ghosts when given, a
//                           metric grid with labelled ticks and a scale bar
//   graph.svg / .png        the pairwise graph at the calibrated positions: edges used by the
//                           global solution (solid green), accepted but not used (solid orange,
//                           e.g. rotation outliers), rejected (dashed red); labels with matches
//                           and rms; in the SVG every edge has a tooltip with its status/reason
//   edges.csv               one row per pair considered (header row first)
//   summary.md              poses (and errors against the truth), per-edge residuals and their
//                           statistics, joint refinement, timings, warnings
//
// Writes files only (no logging, no clock). Ids are escaped for XML, CSV and Markdown.

#include <string>
#include <vector>

#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

struct ReportInput {
  const CalibrationResult* result = nullptr;  // required: poses, edges
  // Optional: per sensor (same order as result->sensors) the description (fov, first angle, max
  // range), background and tracks (sensor frame).
  const AlignedTracks* tracks = nullptr;
  std::vector<PairEstimate> pairs;  // every pair considered (indices into result->sensors)
  const PoseFile* truth = nullptr;  // optional: truth poses drawn as ghosts, errors in summary.md
};

// Writes the files above into `dir` (created with its parents). False with *error (one line,
// naming the file) on I/O failure or without a result.
bool WriteReport(const std::string& dir, const ReportInput& input, std::string* error);

}  // namespace lrfnet::calib
