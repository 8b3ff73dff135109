# tsah_gpu_bench --shutter: the combinations it refuses, checked before the device is looked for (so
# these run without a GPU): motion blur traces the bvh2 layout and needs two timed frames.
if(TARGET tsah_gpu_bench)
  add_test(NAME cli.gpu_bench.shutter.error.layout
           COMMAND tsah_gpu_bench --generate explode:200:4 --frames 4 --shutter 0.5 --layout bvh2,cwbvh)
  set_tests_properties(cli.gpu_bench.shutter.error.layout PROPERTIES
    PASS_REGULAR_EXPRESSION "tsah_gpu_bench: --shutter: motion blur traces the bvh2 layout on the GPU")
  add_test(NAME cli.gpu_bench.shutter.error.frames
           COMMAND tsah_gpu_bench --generate explode:200:4 --frames 1 --shutter 0.5)
  set_tests_properties(cli.gpu_bench.shutter.error.frames PROPERTIES
    PASS_REGULAR_EXPRESSION "tsah_gpu_bench: --shutter needs at least two frames")
  add_test(NAME cli.gpu_bench.shutter.error.mode
           COMMAND tsah_gpu_bench --generate explode:200:4 --shutter-mode open)
  set_tests_properties(cli.gpu_bench.shutter.error.mode PROPERTIES
    PASS_REGULAR_EXPRESSION "--shutter-mode requires --shutter")
endif()
