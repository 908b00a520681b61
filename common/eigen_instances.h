#pragma once
// Eigen's symmetric eigen-solver, compiled once (eigen_instances.cc) instead of in every file that
// uses it: instantiating SelfAdjointEigenSolver<Matrix2d>::compute costs about 5 s of compile time
// per translation unit, more than most of our files take in all. Files that use the solver include
// this header and pass it a matrix of the exact type (Eigen::Matrix2d(expr), not an expression), so
// the declarations below apply; the results are the same bit for bit, the code being the same.

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#define LRFNET_EIGEN_SYMMETRIC_SOLVER(EXTERN, M)                                                  \
  EXTERN template class Eigen::SelfAdjointEigenSolver<M>;                                         \
  EXTERN template Eigen::SelfAdjointEigenSolver<M>& Eigen::SelfAdjointEigenSolver<M>::compute<M>( \
      const Eigen::EigenBase<M>&, int);

#define LRFNET_EIGEN_INSTANCES(EXTERN)                   \
  LRFNET_EIGEN_SYMMETRIC_SOLVER(EXTERN, Eigen::Matrix2d) \
  LRFNET_EIGEN_SYMMETRIC_SOLVER(EXTERN, Eigen::Matrix3d) \
  LRFNET_EIGEN_SYMMETRIC_SOLVER(EXTERN, Eigen::Matrix4d) \
  LRFNET_EIGEN_SYMMETRIC_SOLVER(EXTERN, Eigen::MatrixXd)

#ifndef LRFNET_EIGEN_INSTANCES_DEFINE
LRFNET_EIGEN_INSTANCES(extern)
#endif
