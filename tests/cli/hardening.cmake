# Hostile inputs and situations (docs/bad-inputs.md): each test checks the exit status, that stderr is
# exactly one "tsah: " line, and its text. Files are written at configure time into ${W}/hard.
set(H ${TSAH_CLI_WORK}/hard)
file(MAKE_DIRECTORY ${H})
file(MAKE_DIRECTORY ${H}/folder.obj)

# tsah_expect_error(NAME EXIT_CODE REGEX ARG...): see tests/support/expect_error.cmake.
function(tsah_expect_error name code regex)
  string(REPLACE ";" "@@" args "${ARGN}")
  add_test(NAME ${name} COMMAND ${CMAKE_COMMAND} -DTSAH=$<TARGET_FILE:tsah> -DEXPECT_CODE=${code}
           "-DEXPECT=${regex}" "-DARGS=${args}" -DWORKDIR=${H}
           -P ${PROJECT_SOURCE_DIR}/tests/support/expect_error.cmake)
endfunction()
function(tsah_hard_fixture name fixture)
  set_tests_properties(${name} PROPERTIES FIXTURES_REQUIRED ${fixture})
endfunction()
# tsah_bad_file(NAME FILE REGEX CONTENT): writes CONTENT to ${H}/FILE; `tsah info` on it must fail
# with REGEX.
function(tsah_bad_file name file regex content)
  file(WRITE ${H}/${file} "${content}")
  tsah_expect_error(${name} 1 "${regex}" info ${H}/${file})
endfunction()

# Fixtures: a small animation, a tree for it, a large animation for the memory statement.
add_test(NAME hard.setup.anim COMMAND tsah generate wave -o ${H}/a.tanim --triangles 200 --frames 4)
set_tests_properties(hard.setup.anim PROPERTIES FIXTURES_SETUP hard_anim)
add_test(NAME hard.setup.tree COMMAND tsah optimize ${H}/a.tanim -o ${H}/a.tbvh --frames 2 --eval-frames 2)
set_tests_properties(hard.setup.tree PROPERTIES FIXTURES_REQUIRED hard_anim FIXTURES_SETUP hard_tree)

# ---- 1. Inputs that are not regular files ----------------------------------------------------
execute_process(COMMAND mkfifo ${H}/fifo ${H}/fifo.tanim ${H}/fifo.obj ${H}/fifo.ply ${H}/fifo.json ERROR_QUIET)
tsah_expect_error(hard.fifo.info 1 "fifo: is a FIFO \\(named pipe\\), not a regular file" info ${H}/fifo)
tsah_expect_error(hard.fifo.tanim 1 "fifo.tanim: is a FIFO" info ${H}/fifo.tanim)
tsah_expect_error(hard.fifo.obj 1 "fifo.obj: is a FIFO" info ${H}/fifo.obj)
tsah_expect_error(hard.fifo.ply 1 "fifo.ply: is a FIFO" info ${H}/fifo.ply)
tsah_expect_error(hard.fifo.manifest 1 "fifo.json: is a FIFO" info ${H}/fifo.json)
tsah_expect_error(hard.fifo.tree 1 "fifo: is a FIFO" export ${H}/fifo ${H}/a.tanim -o ${H}/x)
tsah_expect_error(hard.device.tree 1 "/dev/zero: is a character device" trace ${H}/a.tanim /dev/zero --no-images)
tsah_hard_fixture(hard.device.tree hard_anim)
tsah_expect_error(hard.folder.mesh 1 "folder.obj: matches no mesh files" info ${H}/folder.obj)
tsah_expect_error(hard.missing 1 "nothing.tanim: no such file or directory" info ${H}/nothing.tanim)
tsah_expect_error(hard.missing.tree 1 "nothing.tbvh: no such file" export ${H}/nothing.tbvh ${H}/a.tanim -o ${H}/x)
tsah_hard_fixture(hard.missing.tree hard_anim)

# ---- 2. PLY / OFF faces and counts --------------------------------------------------------------
set(PLY_HEAD "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n")
set(PLY_QUAD "${PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n")  # the four vertices and a first good face
tsah_bad_file(hard.ply.missing_vertex bad_index.ply
  "bad_index.ply: face 1 references vertex 77 but the file has 4 vertices" "${PLY_QUAD}3 1 3 77\n")
tsah_bad_file(hard.ply.negative_index negative_index.ply
  "negative_index.ply: face 1 references vertex -3" "${PLY_QUAD}3 1 -3 2\n")
tsah_bad_file(hard.ply.nan nan_vertex.ply
  "nan_vertex.ply: vertex 1 has a NaN or infinite coordinate" "${PLY_HEAD}0 0 0\n1 nan 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n")
tsah_bad_file(hard.ply.word word_vertex.ply
  "word_vertex.ply: vertex 1: property y is not a number: 'zero'" "${PLY_HEAD}0 0 0\n1 zero 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n")
tsah_bad_file(hard.ply.truncated short.ply
  "short.ply: face 1: list length of vertex_indices is missing \\(the file ends early\\)" "${PLY_QUAD}")
tsah_bad_file(hard.ply.two_vertices two_vertex_face.ply
  "two_vertex_face.ply: face 1 has 2 vertices \\(at least 3 needed\\)" "${PLY_QUAD}2 1 3\n")
tsah_bad_file(hard.ply.dropped_face degenerate.ply
  "degenerate.ply: the mesh reader kept 4 of 4 vertices and 1 of 2 faces" "${PLY_QUAD}3 1 1 2\n")
tsah_bad_file(hard.ply.huge_count huge_count.ply
  "huge_count.ply: header declares 4000000000 vertices and 4000000000 faces \\(at least [0-9]+ bytes\\), but only 0 bytes follow it"
  "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 4000000000\nproperty list uchar int vertex_indices\nend_header\n")
tsah_bad_file(hard.ply.format bad_format.ply
  "bad_format.ply: unknown PLY format 'ebcdic'" "ply\nformat ebcdic 1.0\nend_header\n")
file(WRITE ${H}/bad_index.off "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 77\n")
tsah_expect_error(hard.off.missing_vertex 1 "bad_index.off: face 1 references vertex 77 but the file has 4 vertices" optimize ${H}/bad_index.off -o ${H}/never.tbvh)
tsah_bad_file(hard.off.nan nan_vertex.off
  "nan_vertex.off: vertex 1 has a NaN or infinite coordinate" "OFF\n4 1 0\n0 0 0\n1 0 nan\n0 1 0\n1 1 0\n3 0 1 2\n")
tsah_bad_file(hard.off.huge_count huge_count.off
  "huge_count.off: header declares 3000000000 vertices and 3000000000 faces" "OFF\n3000000000 3000000000 0\n0 0 0\n")
tsah_bad_file(hard.off.bad_counts bad_counts.off
  "bad_counts.off: header needs the vertex, face and edge counts, got 'four'" "OFF\nfour 1 0\n")
tsah_bad_file(hard.off.huge_coordinate huge_coord.off
  "huge_coord.off: vertex 1 has coordinate 1e\\+30, beyond the supported magnitude 1e\\+18" "OFF\n3 1 0\n0 0 0\n1e30 0 0\n0 1 0\n3 0 1 2\n")

# ---- OBJ, sequences, manifests, camera files -----------------------------------------------------
file(WRITE ${H}/huge.obj "v 0 0 0\nv 3e38 0 0\nv 0 3e38 0\nf 1 2 3\n")
tsah_expect_error(hard.obj.overflow 1 "huge.obj: vertex 1 has coordinate 3e\\+38, beyond the supported magnitude" optimize ${H}/huge.obj -o ${H}/never.tbvh)
tsah_bad_file(hard.obj.nan nan.obj "nan.obj: vertex 1 has a NaN or infinite coordinate" "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
tsah_bad_file(hard.obj.index bad_index.obj
  "bad_index.obj: line 4: face references vertex 9 but 3 are defined" "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
tsah_bad_file(hard.obj.no_faces no_faces.obj "no_faces.obj: has no faces" "v 0 0 0\nv 1 0 0\nv 0 1 0\n")
tsah_bad_file(hard.obj.empty empty.obj "empty.obj: no vertices" "")
tsah_bad_file(hard.obj.word word.obj "word.obj: line 2: vertex needs three numeric coordinates" "v 0 0 0\nv one 0 0\n")
tsah_expect_error(hard.pattern.none 1 "nomatch_%04d.obj: matches no mesh files" info ${H}/nomatch_%04d.obj)
tsah_expect_error(hard.pattern.two 1 "exactly one %d-style number" info ${H}/f_%d_%d.obj)

tsah_bad_file(hard.manifest.time_overflow time_overflow.json
  "time_overflow.json: invalid JSON: number overflow parsing '1e999'" "{\"frames\": [{\"file\": \"nan.obj\", \"time\": 1e999}]}")
tsah_bad_file(hard.manifest.syntax not_json.json "not_json.json: invalid JSON: .*line 1" "{\"frames\": [")
tsah_bad_file(hard.manifest.no_frames no_frames.json
  "no_frames.json: manifest object has no \"frames\" array" "{\"files\": []}")
tsah_bad_file(hard.manifest.partial_times partial_times.json
  "partial_times.json: times given for 1 of 2 frames: give all or none"
  "{\"frames\": [{\"file\": \"a.obj\", \"time\": 0}, {\"file\": \"b.obj\"}]}")
tsah_bad_file(hard.manifest.entry frame_number.json "frame_number.json: frame 1 is neither a file name nor" "[\"a.obj\", 7]")
tsah_bad_file(hard.manifest.missing_file missing_frame.json "not_there.obj: no such file" "[\"not_there.obj\"]")

file(WRITE ${H}/camera_nan.json "{\"keys\": [{\"time\": 0, \"eye\": [1e39, 0, 0], \"look_at\": [0, 0, 0]}]}")
file(WRITE ${H}/camera_same.json "{\"eye\": [0, 0, 0], \"look_at\": [0, 0, 0]}")
file(WRITE ${H}/camera_order.json "{\"keys\": [{\"time\": 1, \"eye\": [0, 0, 5], \"look_at\": [0, 0, 0]}, {\"time\": 0, \"eye\": [0, 0, 5], \"look_at\": [0, 0, 0]}]}")
file(WRITE ${H}/camera_short.json "{\"eye\": [0, 0], \"look_at\": [0, 0, 0]}")
foreach(c nan same order short)
  set(r_nan "camera_nan.json: 'eye' must hold three finite numbers")
  set(r_same "camera_same.json: .*")
  set(r_order "camera_order.json: camera key times must increase")
  set(r_short "camera_short.json: 'eye' must be an array of three numbers")
  tsah_expect_error(hard.camera.${c} 1 "${r_${c}}" trace ${H}/a.tanim ${H}/a.tbvh --camera ${H}/camera_${c}.json --no-images)
  tsah_hard_fixture(hard.camera.${c} hard_tree)
endforeach()

# ---- .tanim / .tbvh confusion and corruption --------------------------------------------------
file(WRITE ${H}/garbage.tbvh "TSAHBVH")
tsah_expect_error(hard.tbvh.as_animation 1 "a.tbvh: unknown input format '.tbvh'" optimize ${H}/a.tbvh -o ${H}/never.tbvh)
tsah_hard_fixture(hard.tbvh.as_animation hard_tree)
tsah_expect_error(hard.tanim.as_tree 1 "a.tanim: .*" export ${H}/a.tanim ${H}/a.tanim -o ${H}/x)
tsah_hard_fixture(hard.tanim.as_tree hard_anim)
tsah_expect_error(hard.tbvh.not_a_tree 1 "garbage.tbvh: unknown input format '.tbvh'" info ${H}/garbage.tbvh)
