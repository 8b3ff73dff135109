# tsah_two_level_gpu_bench --tlas: the TLAS updates it compares; another name is refused while the
# options are read (before the scene or the device, so this runs without a GPU).
if(TARGET tsah_two_level_gpu_bench)
  add_test(NAME cli.two_level_gpu_bench.tlas_unknown
           COMMAND tsah_two_level_gpu_bench scene.json --tlas sah)
  set_tests_properties(cli.two_level_gpu_bench.tlas_unknown PROPERTIES
    PASS_REGULAR_EXPRESSION "--tlas: sah not in \\{refit,lbvh,hlbvh-sah,all\\}")
endif()
