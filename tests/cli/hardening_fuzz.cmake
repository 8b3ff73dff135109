# Inputs the fuzzers found (scripts/fuzz.sh, docs/fuzzing.md), as command-line cases of
# docs/bad-inputs.md: one "tsah: " line, the exit status, no hang. Uses tsah_expect_error and ${H}
# of hardening.cmake (included before this file).
file(WRITE ${H}/tri.obj "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")

# Found while writing fuzz_scene: a scene whose time range at its rate needs 10^12 keyframes (it
# filled the keyframe times until memory ran out); refused before the times are made.
file(WRITE ${H}/long_scene.json [=[{"fps": 1e6, "time": [0, 1e6], "objects": [{"file": "tri.obj"}]}]=])
tsah_expect_error(hard.scene.keyframes 1
  "long_scene.json: the time range \\[0, 1e\\+06\\] at 1e\\+06 keyframes per second needs more than 2\\^32 keyframes"
  info ${H}/long_scene.json)

# fuzz_mesh finding: a PLY whose end_header is glued to other text made OpenMesh's header reader loop
# forever at the end of the file (`tsah info` hung); the header must end with an end_header line.
file(WRITE ${H}/glued_header.ply "ply\nformat ascii 1.0*end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
tsah_expect_error(hard.ply.glued_end_header 1
  "glued_header.ply: not a PLY file \\(no 'ply' line ... 'end_header' line\\)" info ${H}/glued_header.ply)

# fuzz_mesh finding: a PLY format line whose version is not a number made OpenMesh loop forever.
file(WRITE ${H}/bad_version.ply "ply\nformat ascii one\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
tsah_expect_error(hard.ply.bad_version 1 "bad_version.ply: unsupported PLY version 'one' \\(1.0 expected\\)"
  info ${H}/bad_version.ply)

# fuzz_mesh finding: counts on the OFF keyword line (OpenMesh skips that line, so it read other numbers
# as the counts and reserved gigabytes before failing).
file(WRITE ${H}/counts_on_keyword_line.off "OFF 0\n0\n\n 04777777777777777\n1 0\n4 0 1 2 3\n")
tsah_expect_error(hard.off.counts_on_keyword_line 1
  "counts_on_keyword_line.off: the OFF line holds '0' after the keyword \\(the counts go on the next line\\)"
  info ${H}/counts_on_keyword_line.off)

# fuzz_mesh finding: a PLY property line without its name made OpenMesh take end_header as the name
# and loop forever; every header statement must hold its words on its own line.
file(WRITE ${H}/unnamed_property.ply "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
tsah_expect_error(hard.ply.unnamed_property 1 "unnamed_property.ply: a property of element face has no name"
  info ${H}/unnamed_property.ply)

# fuzz_mesh finding (UndefinedBehaviorSanitizer): an ASCII PLY list length of 2e21 was converted to an
# integer that cannot hold it.
file(WRITE ${H}/huge_list.ply "${PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n1 1 0\n2e21 0 1 2\n3 1 3 2\n")
tsah_expect_error(hard.ply.huge_list_length 1 "huge_list.ply: face 0: bad list length 2e\\+21" info ${H}/huge_list.ply)

# TSAH_MEMORY_LIMIT_MB caps the memory the statements count as available (the scene fuzzer's budget,
# or a container's share): a resample that fits the machine is refused under a 1 MiB cap.
tsah_expect_error(hard.memory.limit_env 1 "more than the 1 MiB of memory available"
  resample ${H}/a.tanim -o ${H}/never_limited.tanim --frames 100000)
set_tests_properties(hard.memory.limit_env PROPERTIES ENVIRONMENT "TSAH_MEMORY_LIMIT_MB=1" FIXTURES_REQUIRED hard_anim)
