# The device side of both SOPAS dialects (framer, typed arguments, the emulator's device model) on
# arbitrary client bytes. The fuzz build has no tools/ libraries: there the sources are compiled
# into the target (so libFuzzer also sees their coverage). Seeds: sopas_seeds.cc.
if(LRFNET_FUZZ)
  lrfnet_fuzz_target(sopas_fuzz
    SOURCES sopas_fuzz.cc
            ${PROJECT_SOURCE_DIR}/firmware_tracker/cola/sopas_framer.cc
            ${PROJECT_SOURCE_DIR}/firmware_tracker/cola/sopas_value.cc
            ${PROJECT_SOURCE_DIR}/tools/sopas_device.cc
            ${PROJECT_SOURCE_DIR}/tools/sopas_fields.cc
    LIBS lrfnet_cola lrfnet_capture)
else()
  lrfnet_fuzz_target(sopas_fuzz SOURCES sopas_fuzz.cc LIBS lrfnet_sopas_device)
endif()
if(TARGET make_fuzz_corpus)
  target_sources(make_fuzz_corpus PRIVATE sopas_seeds.cc)
  target_link_libraries(make_fuzz_corpus PRIVATE lrfnet_sopas)
endif()
