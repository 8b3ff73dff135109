# Scene files, data paths, point-cache times, names and options that would be ignored
# (docs/bad-inputs.md). Uses tsah_expect_error and the fixtures of hardening.cmake, which sorts
# first in tests/CMakeLists.txt's glob.
set(H ${TSAH_CLI_WORK}/hard)
set(A ${H}/a.tanim)

# ---- Scene files: subdivision, data paths, object fields -----------------------------------------
# A tetrahedron whose last face is wound inwards, and one with a third triangle on edge 1-2.
file(WRITE ${H}/flipped.obj "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 4 3\n")
file(WRITE ${H}/fin.obj "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nf 1 2 5\n")
foreach(c flipped fin)
  file(WRITE ${H}/subdivide_${c}.json "{\"objects\": [{\"name\": \"rock\", \"file\": \"${c}.obj\", \"subdivide\": 2}]}")
endforeach()
tsah_expect_error(hard.subdivide.flipped 1
  "subdivide_flipped.json: object 'rock': flipped: cannot subdivide: triangle 3 walks edge 1-2 in the same direction as triangle 0: the faces are not consistently oriented"
  info ${H}/subdivide_flipped.json)
tsah_expect_error(hard.subdivide.non_manifold 1
  "subdivide_fin.json: object 'rock': fin: cannot subdivide: edge 0-1 is shared by more than two triangles \\(0, 1, 4\\): a non-manifold edge"
  info ${H}/subdivide_fin.json)

tsah_bad_file(hard.data.climb data_climb.json
  "data_climb.json: object 'x': \"data:../../../etc/passwd\" must name a path inside the data folder \\(relative, without \"..\"\\)"
  "{\"objects\": [{\"name\": \"x\", \"file\": \"data:../../../etc/passwd\"}]}")
tsah_bad_file(hard.data.absolute data_absolute.json
  "data_absolute.json: object 'x': \"data:/etc/passwd\" must name a path inside the data folder"
  "{\"objects\": [{\"name\": \"x\", \"file\": \"data:/etc/passwd\"}]}")
tsah_bad_file(hard.scene.empty_file empty_file.json
  "empty_file.json: object 'x': \"file\" is empty \\(name an input, relative to the scene file's folder\\)"
  "{\"objects\": [{\"name\": \"x\", \"file\": \"\"}]}")
tsah_bad_file(hard.scene.offset_twice offset_twice.json
  "offset_twice.json: object 'x': both \"offset\" and \"time\": {\"offset\"} are given; keep one"
  "{\"objects\": [{\"name\": \"x\", \"file\": \"a.tanim\", \"offset\": 1, \"time\": {\"offset\": 2}}]}")
tsah_hard_fixture(hard.scene.offset_twice hard_anim)
# In a scene, MESH+CACHE finds the cache beside the scene file (the test runs in another folder).
file(MAKE_DIRECTORY ${H}/cache_scene)
add_test(NAME hard.setup.cache COMMAND tsah resample ${A} -o ${H}/cache_scene/c.pc2)
set_tests_properties(hard.setup.cache PROPERTIES FIXTURES_REQUIRED hard_anim FIXTURES_SETUP hard_cache)
file(WRITE ${H}/cache_scene/s.json "{\"objects\": [{\"file\": \"c.obj+c.pc2\"}]}")
add_test(NAME hard.scene.mesh_cache COMMAND tsah info ${H}/cache_scene/s.json --json)
set_tests_properties(hard.scene.mesh_cache PROPERTIES FIXTURES_REQUIRED hard_cache
  PASS_REGULAR_EXPRESSION "\"triangles\":[1-9]")

# ---- Point caches whose times float32 cannot hold ------------------------------------------------
file(WRITE ${H}/tri.obj "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
file(WRITE ${H}/late.json "{\"frames\": [{\"file\": \"tri.obj\", \"time\": 0}, {\"file\": \"tri.obj\", \"time\": 1e39}]}")
foreach(ext pc2 mdd)
  string(TOUPPER ${ext} EXT)
  tsah_expect_error(hard.pointcache.float_time.${ext} 1
    "late: keyframe 1 at time 1e\\+39 does not fit the float32 times of the ${EXT} format"
    resample ${H}/late.json -o ${H}/late.${ext})
endforeach()

# ---- Coordinates too small for float32 surface areas, names with control characters --------------
file(WRITE ${H}/tiny.obj "v 0 0 0\nv 1e-30 0 0\nv 0 1e-30 0\nf 1 2 3\n")
tsah_expect_error(hard.obj.tiny 1
  "tiny.obj: the model spans only 1e-30 \\(the largest side of its bounding box\\), below the supported 1e-18 \\(surface areas would underflow to zero\\); scale it up"
  info ${H}/tiny.obj)
tsah_expect_error(hard.name.control 1 "line\\\\x0abreak.tanim: no such file" info "${H}/line\nbreak.tanim")

# ---- Options that would be ignored (usage errors, exit 2) ----------------------------------------
tsah_expect_error(hard.export.boxes_layout 2 "--layout excludes --boxes" export ${H}/a.tbvh ${A} --boxes --layout bvh8 -o ${H}/b.obj)
tsah_expect_error(hard.export.style_without_boxes 2 "--style requires --boxes" export ${H}/a.tbvh ${A} --style lines -o ${H}/x)
tsah_expect_error(hard.opt.overlap_without_segments 2 "--overlap goes with --segments \\(a tree set\\)" optimize ${A} -o ${H}/n.tbvh --overlap 0.5)
tsah_expect_error(hard.opt.max_trees_without_auto 2 "--max-trees goes with --segments auto" optimize ${A} -o ${H}/n.tbvh --segments 2 --max-trees 3)
tsah_expect_error(hard.opt.reference_frames_with_cost 2 "--reference-frames goes with --segments auto and a relative --budget"
  optimize ${A} -o ${H}/n.tbvh --segments auto --budget-cost 5 --reference-frames 4)
tsah_expect_error(hard.trace.out_no_images 2 "--out excludes --no-images" trace ${A} ${H}/a.tbvh --no-images --out ${H}/t)
tsah_expect_error(hard.trace.ao_both 2 "--ao-distance excludes --ao-fraction" trace ${A} ${H}/a.tbvh --ao-distance 1 --ao-fraction 0.2)
tsah_expect_error(hard.trace.isa_cuda 2 "--isa chooses the CPU's kernels; it does not go with --device cuda" trace ${A} ${H}/a.tbvh --isa sse --device cuda --no-images)
tsah_expect_error(hard.trace.triangles_cuda 2 "--triangles chooses how the CPU's wide trees hold triangles; it does not go with --device cuda" trace ${A} ${H}/a.tbvh --triangles woop --device cuda --no-images)
tsah_expect_error(hard.trace.triangles_bvh2 2 "--triangles vertices needs a wide layout \\(--layout bvh4, bvh8 or auto\\); bvh2 holds Woop triangles" trace ${A} ${H}/a.tbvh --triangles vertices --layout bvh2 --no-images)
tsah_expect_error(hard.trace.triangles_name 2 "--triangles: quads not in" trace ${A} ${H}/a.tbvh --triangles quads --no-images)
tsah_expect_error(hard.trace.frames_range 2 "--frames: Value 100001 not in range 1 to 100000" trace ${A} ${H}/a.tbvh --frames 100001 --no-images)
foreach(t hard.export.boxes_layout hard.export.style_without_boxes hard.trace.out_no_images hard.trace.ao_both
          hard.trace.isa_cuda hard.trace.triangles_cuda hard.trace.triangles_bvh2 hard.trace.triangles_name
          hard.trace.frames_range)
  tsah_hard_fixture(${t} hard_tree)
endforeach()
foreach(t hard.opt.overlap_without_segments hard.opt.max_trees_without_auto hard.opt.reference_frames_with_cost)
  tsah_hard_fixture(${t} hard_anim)
endforeach()

# ---- What used to be refused ----------------------------------------------------------------------
# --isa sse with the default layout: the widest layout SSE has kernels for.
add_test(NAME hard.trace.isa_sse_auto COMMAND tsah trace ${A} ${H}/a.tbvh --isa sse --frames 1 --width 8 --height 8 --no-images)
set_tests_properties(hard.trace.isa_sse_auto PROPERTIES FIXTURES_REQUIRED hard_tree PASS_REGULAR_EXPRESSION "bvh4 \\(sse\\)")
# tsah info SET.tbvh ANIMATION: each tree over the frames of its part.
add_test(NAME hard.setup.set COMMAND tsah optimize ${A} -o ${H}/set.tbvh --segments 2 --frames 2 --eval-frames 4)
set_tests_properties(hard.setup.set PROPERTIES FIXTURES_REQUIRED hard_anim FIXTURES_SETUP hard_set)
add_test(NAME hard.info.set_over_animation COMMAND tsah info ${H}/set.tbvh ${A})
set_tests_properties(hard.info.set_over_animation PROPERTIES FIXTURES_REQUIRED hard_set
  PASS_REGULAR_EXPRESSION "tree set +[^\n]*set.tbvh \\(2 trees\\)\n.*\ntree 0 +used for t 0 \\.\\. [0-9.]+ .*average cost [0-9.]+.*\ntree 1 +used for t [0-9.]+ \\.\\. [0-9.]+ .*average cost [0-9.]+")
add_test(NAME hard.info.set_over_animation.json COMMAND tsah info ${H}/set.tbvh ${A} --json)
set_tests_properties(hard.info.set_over_animation.json PROPERTIES FIXTURES_REQUIRED hard_set
  PASS_REGULAR_EXPRESSION "\"tree_set\":.*\"trees\":\\[\\{.*\"average_cost\":[0-9.]+.*\"index\":0.*\"index\":1")
