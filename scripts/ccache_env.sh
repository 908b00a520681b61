# Sourced by build.sh and test.sh (after cd to the checkout): compile through ccache when it is installed,
# so a second run, another build tree or another clone of the same sources recompiles only what changed.
# LRFNET_CCACHE=0 compiles without it. Paths are hashed relative to the checkout's parent (a clone elsewhere
# and ../shared beside it hit the same entries); a new build tree takes the launcher on its first configure.
if [ "${LRFNET_CCACHE:-1}" != 0 ] && command -v ccache >/dev/null 2>&1; then
  export CMAKE_C_COMPILER_LAUNCHER=ccache CMAKE_CXX_COMPILER_LAUNCHER=ccache
  CCACHE_BASEDIR=$(cd .. && pwd)
  export CCACHE_BASEDIR CCACHE_NOHASHDIR=true CCACHE_SLOPPINESS=pch_defines,time_macros
fi
