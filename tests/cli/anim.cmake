# CLI smoke tests for libanim's commands: generate -> info -> resample, and one-line errors.
set(W ${TSAH_CLI_WORK})
add_test(NAME cli.version COMMAND tsah --version)
set_tests_properties(cli.version PROPERTIES PASS_REGULAR_EXPRESSION "tsah [0-9]+\\.[0-9]+")

foreach(kind explode wave swap)
  add_test(NAME cli.generate.${kind}
           COMMAND tsah generate ${kind} -o ${W}/${kind}.tanim --triangles 2000 --frames 12 --seed 3)
  set_tests_properties(cli.generate.${kind} PROPERTIES FIXTURES_SETUP sample_${kind})
endforeach()

add_test(NAME cli.info.json COMMAND tsah info ${W}/explode.tanim --json)
set_tests_properties(cli.info.json PROPERTIES FIXTURES_REQUIRED sample_explode
  PASS_REGULAR_EXPRESSION "\"frames\":12.*\"triangles\":[0-9]+.*\"vertices\":[0-9]+")

add_test(NAME cli.resample COMMAND tsah resample ${W}/wave.tanim -o ${W}/wave5.tanim --frames 5)
set_tests_properties(cli.resample PROPERTIES FIXTURES_REQUIRED sample_wave FIXTURES_SETUP wave5
  PASS_REGULAR_EXPRESSION "5 keyframes \\(from 12\\)")
add_test(NAME cli.resample.info COMMAND tsah info ${W}/wave5.tanim --json)
set_tests_properties(cli.resample.info PROPERTIES FIXTURES_REQUIRED wave5
  PASS_REGULAR_EXPRESSION "\"frames\":5,.*\"time\":\\[0\\.0,11\\.0\\]")

# Bad input: one line on stderr, non-zero exit, no crash.
add_test(NAME cli.error.missing COMMAND tsah info ${W}/does-not-exist.obj)
set_tests_properties(cli.error.missing PROPERTIES WILL_FAIL TRUE)
add_test(NAME cli.error.missing.message COMMAND tsah info ${W}/does-not-exist.obj)
set_tests_properties(cli.error.missing.message PROPERTIES
  PASS_REGULAR_EXPRESSION "^tsah: .*does-not-exist.obj: no such file or directory\n$")
file(WRITE ${W}/garbage.tanim "this is not an animation")
add_test(NAME cli.error.garbage COMMAND tsah info ${W}/garbage.tanim)
set_tests_properties(cli.error.garbage PROPERTIES PASS_REGULAR_EXPRESSION "garbage.tanim: .*(magic|truncated)")
add_test(NAME cli.error.generate.kind COMMAND tsah generate implode -o ${W}/x.tanim)
set_tests_properties(cli.error.generate.kind PROPERTIES WILL_FAIL TRUE)
