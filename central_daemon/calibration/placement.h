#pragma once
// How well a placement of the sensors explains all the raw observations (pipeline: the judge of
// the hypotheses where the pose graph's cycles cannot decide).
//
// Track cost. For every ordered pair of placed sensors (r, s) and every stride-th grid step at
// which both have tracks, each of r's samples is mapped into s's frame (as the body centre of the
// measurement model, CentreOf) and costs the squared Mahalanobis distance to the nearest of s's
// samples at that step (eq. 6 with both samples' CentreCovariance, the prior size's uncertainty
// and model_sigma_m), truncated at gate^2 (eqs. 7-8: nobody there, or someone else). Every such
// sample is counted whatever the placement, so a placement cannot lower the cost by moving
// observations out of each other's way: an observation without a partner costs the full gate.

// Background cost. For every pair with both background snapshots, the consistency score of the
// backgrounds (icp.h ScoreBackgrounds) times their points: the number of background points that do
// not lie on the other's background, in the same truncated-quadratic units.
//
// The total is in units of independent squared sigmas: the track cost is multiplied by
// stride / correlation_steps (smoothed samples are correlated in time) and the background cost
// divided by background_correlation (neighbouring beams share their errors), so that a difference
// between two placements reads like a chi-square difference.
//
// Pure; thread-safe.

#include <cstddef>
#include <vector>

#include "central_daemon/calibration/icp.h"
#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

struct PlacementOptions {
  std::size_t stride = 4;
  double correlation_steps = 20.0;
  double gate = 3.0;
  double model_sigma_m = 0.05;
  double background_correlation = 4.0;
  IcpOptions icp;  // the score's parameters
};

struct PlacementCost {
  double total = 0.0;  // track + background, independent units
  double track = 0.0;
  double background = 0.0;
  std::size_t observations = 0;  // r samples counted
};

// `world_from_sensor`, `placed`: one entry per tracks.sensors entry; only placed sensors count.
PlacementCost EvaluatePlacement(const AlignedTracks& tracks,
                                const std::vector<Pose2>& world_from_sensor,
                                const std::vector<bool>& placed, const PlacementOptions& options);

}  // namespace lrfnet::calib
