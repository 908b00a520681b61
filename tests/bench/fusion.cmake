# Fusion accuracy, id continuity and update time on synthetic six-sensor scenes with emulated
# trackers (occlusion, losses, id swaps) and slightly wrong poses.
add_executable(fusion_benchmark fusion_benchmark.cc)
target_link_libraries(fusion_benchmark PRIVATE lrfnet_fusion)
lrfnet_warnings(fusion_benchmark)
