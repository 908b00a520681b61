// The one place the declarations of eigen_instances.h are instantiated.
#define LRFNET_EIGEN_INSTANCES_DEFINE
#include "common/eigen_instances.h"

LRFNET_EIGEN_INSTANCES()
