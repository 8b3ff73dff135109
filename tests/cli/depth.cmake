# Trees of inputs that used to come out deeper than the runtimes' traversal stack (docs/optimizer.md,
# "Depth bound"): 2,000 identical triangles (the sequential optimizer chained them 161 levels deep,
# which `tsah trace` and `tsah export` then refused). Every method's tree now traces and exports.
set(D ${TSAH_CLI_WORK}/depth)
file(MAKE_DIRECTORY ${D})
set(same_obj "")
foreach(i RANGE 1 2000)
  string(APPEND same_obj "v 0 0 0\nv 1 0 0\nv 0 1 0\n")
endforeach()
foreach(i RANGE 0 1999)
  math(EXPR a "3 * ${i} + 1")
  math(EXPR b "3 * ${i} + 2")
  math(EXPR c "3 * ${i} + 3")
  string(APPEND same_obj "f ${a} ${b} ${c}\n")
endforeach()
file(WRITE ${D}/same.obj "${same_obj}")

foreach(method tsah0 sahstar)
  if(method STREQUAL "tsah0")
    set(k_args --k 0)
  else()
    set(k_args --method sahstar)
  endif()
  add_test(NAME cli.depth.${method}.optimize COMMAND tsah optimize ${D}/same.obj -o ${D}/same_${method}.tbvh
                                                     --optimizer sequential ${k_args})
  set_tests_properties(cli.depth.${method}.optimize PROPERTIES FIXTURES_SETUP depth_${method})
  add_test(NAME cli.depth.${method}.info COMMAND tsah info ${D}/same_${method}.tbvh --json)
  set_tests_properties(cli.depth.${method}.info PROPERTIES FIXTURES_REQUIRED depth_${method}
    PASS_REGULAR_EXPRESSION "\"depth\":([0-9]|[0-9][0-9]|1[01][0-9]|12[0-8])[,}]")
  add_test(NAME cli.depth.${method}.trace COMMAND tsah trace ${D}/same.obj ${D}/same_${method}.tbvh --frames 1
                                                  --width 16 --height 16 --no-images)
  set_tests_properties(cli.depth.${method}.trace PROPERTIES FIXTURES_REQUIRED depth_${method}
    PASS_REGULAR_EXPRESSION "update_ms +trace_ms +total_ms")
  foreach(layout bvh2 bvh8)
    add_test(NAME cli.depth.${method}.export.${layout}
             COMMAND tsah export ${D}/same_${method}.tbvh ${D}/same.obj --layout ${layout}
                     -o ${D}/same_${method}_${layout})
    set_tests_properties(cli.depth.${method}.export.${layout} PROPERTIES FIXTURES_REQUIRED depth_${method}
      PASS_REGULAR_EXPRESSION "wrote .*same_${method}_${layout}: [0-9]+ nodes")
  endforeach()
endforeach()
