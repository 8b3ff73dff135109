# Outputs that come in sets (a point cache and its topology, an exported tree's buffers and header,
# a box mesh and its materials) appear whole or not at all: one file impossible, a full disk, a
# signal between staging and commit, two writers at once (tests/support/output_sets.sh). Uses the
# fixtures of hardening.cmake.
foreach(case resample_topology_blocked boxes_obj_blocked export_buffer_blocked full_disk sigterm sigquit concurrent)
  add_test(NAME sets.${case} COMMAND bash ${PROJECT_SOURCE_DIR}/tests/support/output_sets.sh ${case}
           $<TARGET_FILE:tsah> ${TSAH_CLI_WORK}/sets ${TSAH_CLI_WORK}/hard/a.tanim ${TSAH_CLI_WORK}/hard/a.tbvh)
  set_tests_properties(sets.${case} PROPERTIES FIXTURES_REQUIRED "hard_anim;hard_tree" TIMEOUT 120)
endforeach()
