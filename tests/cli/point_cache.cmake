# CLI smoke tests for point caches: resample to .pc2/.mdd (with the topology OBJ), load the pair.
set(W ${TSAH_CLI_WORK})
foreach(ext pc2 mdd)
  add_test(NAME cli.pointcache.write.${ext} COMMAND tsah resample ${W}/wave.tanim -o ${W}/wave_cache.${ext} --frames 4)
  set_tests_properties(cli.pointcache.write.${ext} PROPERTIES FIXTURES_REQUIRED sample_wave FIXTURES_SETUP cache_${ext}
    PASS_REGULAR_EXPRESSION "wave_cache.${ext}: 4 keyframes.*topology .*wave_cache.obj")
  add_test(NAME cli.pointcache.read.${ext} COMMAND tsah info ${W}/wave_cache.obj+${W}/wave_cache.${ext} --json)
  set_tests_properties(cli.pointcache.read.${ext} PROPERTIES FIXTURES_REQUIRED cache_${ext}
    PASS_REGULAR_EXPRESSION "\"frames\":4,.*\"time\":\\[0\\.0,11\\.0")
endforeach()
add_test(NAME cli.pointcache.alone COMMAND tsah info ${W}/wave_cache.pc2)
set_tests_properties(cli.pointcache.alone PROPERTIES FIXTURES_REQUIRED cache_pc2
  PASS_REGULAR_EXPRESSION "^tsah: .*wave_cache.pc2: a point cache holds positions only.*\n$")
