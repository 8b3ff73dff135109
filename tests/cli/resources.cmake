# Resource statements with headroom (docs/architecture.md, "Memory"): the whole request is computed
# before anything is allocated and refused above the budget, here made small with TSAH_MEMORY_LIMIT_MB.
# Uses tsah_expect_error and the fixtures of hardening.cmake.
set(R ${TSAH_CLI_WORK}/resources)
file(MAKE_DIRECTORY ${R})
function(tsah_memory_limited name mib)
  set_tests_properties(${name} PROPERTIES ENVIRONMENT "TSAH_MEMORY_LIMIT_MB=${mib}" FIXTURES_REQUIRED "hard_anim;hard_tree")
endfunction()

# resample counts the file it encodes too: 100,000 frames of a.tanim take 139 MiB as an animation
# and twice the positions again as a point cache, so they are refused under 200 MiB.
tsah_expect_error(res.resample.whole_request 1
  "wave: 100000 frames would need [0-9]+ MiB, more than the 200 MiB of memory available \\(TSAH_MEMORY_LIMIT_MB\\)"
  resample ${H}/a.tanim -o ${R}/never.pc2 --frames 100000)
tsah_memory_limited(res.resample.whole_request 200)

# A 90-byte scene: a.tanim baked at 1000 keyframes per second over 1000 s.
file(WRITE ${R}/fast.json "{\"fps\": 1000, \"time\": [0, 1000], \"objects\": [{\"file\": \"../hard/a.tanim\"}]}")
tsah_expect_error(res.scene.keyframes 1
  "fast.json: object 'a': 1 instances take the scene to 200 triangles x 1000001 keyframes: the bake would need [0-9]+ MiB, more than the 64 MiB of memory available"
  info ${R}/fast.json)
tsah_memory_limited(res.scene.keyframes 64)

# 40 nested scene files, 2 instances each: 2^40 copies of a.tanim, refused by the outermost scene
# from the descriptions alone (no level is baked), within the test's 20 s.
foreach(level RANGE 39)
  math(EXPR next "${level} + 1")
  set(inner "nest${next}.json")
  if(level EQUAL 39)
    set(inner "../hard/a.tanim")
  endif()
  file(WRITE ${R}/nest${level}.json
       "{\"objects\": [{\"name\": \"inner\", \"file\": \"${inner}\", \"instances\": [{}, {\"transform\": {\"translate\": [1, 0, 0]}}]}]}")
endforeach()
tsah_expect_error(res.scene.nested 1
  "nest0.json: object 'inner': 2 instances of a scene of 109951162777600 triangles \\(counted from its scene files\\) would make more than 2\\^32 triangles or vertices"
  info ${R}/nest0.json)
set_tests_properties(res.scene.nested PROPERTIES TIMEOUT 20 FIXTURES_REQUIRED hard_anim)

# The renderer's buffers are stated (about 13 GiB at 16384 x 16384) and the limit applies.
tsah_expect_error(res.trace.image 1
  "a.tanim: tracing 16384x16384 frames would need 1[0-9][0-9][0-9][0-9] MiB, more than the 1000 MiB of memory available \\(TSAH_MEMORY_LIMIT_MB\\)"
  trace ${H}/a.tanim ${H}/a.tbvh --width 16384 --height 16384 --frames 1 --no-images)
tsah_memory_limited(res.trace.image 1000)

# An archive in the bench's data folder is checked against its declared expanded size before it
# is unpacked: 4 MiB of zeros (a few hundred bytes as .tar.xz) under a 1 MiB limit.
file(MAKE_DIRECTORY ${R}/zeros ${R}/data)
execute_process(COMMAND truncate -s 4M ${R}/zeros/big.bin)
execute_process(COMMAND tar -cJf ${R}/data/zeros.tar.xz -C ${R}/zeros big.bin)
# (The bench logs its progress on stderr too: the error is its last line.)
add_test(NAME res.bench.archive COMMAND tsah bench --data ${R}/data --out ${R}/bench --list)
set_tests_properties(res.bench.archive PROPERTIES ENVIRONMENT "TSAH_MEMORY_LIMIT_MB=1" PASS_REGULAR_EXPRESSION
  "\ntsah: [^\n]*zeros.tar.xz: unpacking would need 4 MiB, more than the 1 MiB of memory available \\(TSAH_MEMORY_LIMIT_MB\\)\n$")
add_test(NAME res.bench.archive_not_unpacked COMMAND sh -c "! find '${R}/bench' -name big.bin | grep -q .")
set_tests_properties(res.bench.archive_not_unpacked PROPERTIES DEPENDS res.bench.archive)
