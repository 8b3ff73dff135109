# Command-line misuse (exit 2, one "tsah: " line, compact numbers) and outputs that would destroy
# or half-write something (exit 1). Uses tsah_expect_error and the fixtures of hardening.cmake,
# which sorts first in tests/CMakeLists.txt's glob.
set(H ${TSAH_CLI_WORK}/hard)
set(A ${H}/a.tanim)

# ---- 3. Numbers: NaN, infinities, negatives, ranges (usage errors, exit 2) ----------------------
tsah_expect_error(hard.opt.ct_nan 2 "--ct: must be a positive finite number, got nan" optimize ${A} -o ${H}/n.tbvh --ct nan)
tsah_expect_error(hard.opt.ci_inf 2 "--ci: must be a positive finite number, got inf" optimize ${A} -o ${H}/n.tbvh --ci inf)
tsah_expect_error(hard.opt.ct_negative 2 "--ct: must be a positive finite number, got -1" optimize ${A} -o ${H}/n.tbvh --ct -1)
tsah_expect_error(hard.opt.ct_zero 2 "--ct: must be a positive finite number, got 0" optimize ${A} -o ${H}/n.tbvh --ct 0)
tsah_expect_error(hard.opt.min_improvement_nan 2 "--min-improvement: must be a finite number, got nan" optimize ${A} -o ${H}/n.tbvh --min-improvement nan)
tsah_expect_error(hard.opt.min_improvement_range 2 "--min-improvement: Value 2 not in range 0 to 1 \\(tsah --help" optimize ${A} -o ${H}/n.tbvh --min-improvement 2)
tsah_expect_error(hard.opt.time_limit_nan 2 "--time-limit: must be a non-negative finite number, got nan" optimize ${A} -o ${H}/n.tbvh --time-limit nan)
tsah_expect_error(hard.opt.time_limit_overflow 2 "--time-limit: must be a non-negative finite number, got 1e999" optimize ${A} -o ${H}/n.tbvh --time-limit 1e999)
tsah_expect_error(hard.opt.k_range 2 "--k: Value 99 not in range 0 to 16" optimize ${A} -o ${H}/n.tbvh --k 99)
tsah_expect_error(hard.opt.method 2 "--method: bogus not in" optimize ${A} -o ${H}/n.tbvh --method bogus)
tsah_expect_error(hard.eval.ct_nan 2 "--ct: must be a positive finite number, got nan" evaluate ${A} --ct nan)
tsah_expect_error(hard.eval.time_limit_inf 2 "--time-limit: must be a non-negative finite number, got inf" evaluate ${A} --time-limit inf)
tsah_expect_error(hard.export.time_nan 2 "--time: must be a finite number, got nan" export ${H}/a.tbvh ${A} --time nan -o ${H}/x)
tsah_expect_error(hard.export.frame_negative 2 "--frame: must be a non-negative finite number, got -1" export ${H}/a.tbvh ${A} --frame -1 -o ${H}/x)
tsah_expect_error(hard.export.frame_range 2 "--frame 99 is out of range: .*a.tanim has 4 keyframes \\(0..3\\)" export ${H}/a.tbvh ${A} --frame 99 -o ${H}/x)
tsah_hard_fixture(hard.export.frame_range hard_tree)
tsah_expect_error(hard.fps_nan 2 "--fps: must be a finite number, got nan" info ${A} --fps nan)
tsah_expect_error(hard.trace.fov 2 "--fov must be between 0 and 180 degrees" trace ${A} ${H}/a.tbvh --fov 200 --no-images)
tsah_hard_fixture(hard.trace.fov hard_tree)
tsah_expect_error(hard.trace.eye 2 "--eye expects x,y,z \\(three comma-separated numbers\\), got '1,2'" trace ${A} ${H}/a.tbvh --eye 1,2 --look-at 0,0,0 --no-images)
tsah_hard_fixture(hard.trace.eye hard_tree)
tsah_expect_error(hard.trace.width 2 "--width: Value 0 not in range 1 to 16384" trace ${A} ${H}/a.tbvh --width 0)
tsah_expect_error(hard.resample.frames_zero 2 "--frames: Value 0 not in range 1 to 1000000" resample ${A} -o ${H}/n.tanim --frames 0)
tsah_expect_error(hard.generate.triangles_negative 2 "Could not convert: --triangles = -5" generate wave -o ${H}/n.tanim --triangles -5)

# ---- 9. Parse errors: exit 2, one line with the prefix ----------------------------------------------
tsah_expect_error(hard.cli.unknown_option 2 "The following argument was not expected: --bogus" optimize ${A} -o ${H}/n.tbvh --bogus)
tsah_expect_error(hard.cli.missing_input 2 "INPUT is required" optimize -o ${H}/n.tbvh)
tsah_expect_error(hard.cli.no_command 2 "A subcommand is required")
tsah_expect_error(hard.cli.unknown_command 2 "A subcommand is required" frobnicate)
tsah_expect_error(hard.cli.missing_value 2 "--ct: 1 required FLOAT:POSITIVE missing" optimize ${A} -o ${H}/n.tbvh --ct)
tsah_expect_error(hard.cli.not_a_number 2 "Could not convert: --seed = twelve" optimize ${A} -o ${H}/n.tbvh --seed twelve)
tsah_expect_error(hard.cli.excludes 2 "--frame excludes --time" export ${H}/a.tbvh ${A} --frame 1 --time 0.5 -o ${H}/x)

# ---- 4. Outputs that would destroy an input or hold the wrong kind of data --------------------
# (copies, so a failure of the protection cannot damage the other tests' fixtures)
add_test(NAME hard.setup.copies COMMAND ${CMAKE_COMMAND} -E copy ${A} ${H}/same.tanim)
set_tests_properties(hard.setup.copies PROPERTIES FIXTURES_REQUIRED hard_anim FIXTURES_SETUP hard_copies)
tsah_expect_error(hard.out.same_as_input 1 "same.tanim: is also an input of this command; refusing to overwrite it" resample ${H}/same.tanim -o ${H}/folder.obj/../same.tanim)
tsah_hard_fixture(hard.out.same_as_input hard_copies)
tsah_expect_error(hard.out.resample_in_place 1 "same.tanim: is also an input of this command" resample same.tanim -o ./same.tanim)
tsah_hard_fixture(hard.out.resample_in_place hard_copies)
add_test(NAME hard.out.input_intact COMMAND tsah info ${H}/same.tanim --json)
set_tests_properties(hard.out.input_intact PROPERTIES PASS_REGULAR_EXPRESSION "\"frames\":4"
  DEPENDS "hard.out.same_as_input;hard.out.resample_in_place;hard.out.tree_over_input" FIXTURES_REQUIRED hard_copies)
tsah_expect_error(hard.out.tree_over_input 1 "same.tanim: tree files must end in .tbvh" optimize ${H}/same.tanim -o ${H}/same.tanim)
tsah_hard_fixture(hard.out.tree_over_input hard_copies)
tsah_expect_error(hard.out.tree_not_tbvh 1 "tree.tanim: tree files must end in .tbvh" optimize ${A} -o ${H}/tree.tanim)
tsah_expect_error(hard.out.anim_as_tbvh 1 "x.tbvh: animation files must end in .tanim" generate wave -o ${H}/x.tbvh)
tsah_expect_error(hard.out.resample_not_tanim 1 "r.obj: animation files must end in .tanim" resample ${A} -o ${H}/r.obj)
tsah_expect_error(hard.out.pattern_format 1 "exactly one %d-style number" generate wave -o ${H}/f_%s_%d.obj)
tsah_expect_error(hard.out.pattern_ext 1 "f_%d.ply: OBJ sequence files must end in .obj" generate wave -o ${H}/f_%d.ply)
tsah_expect_error(hard.out.missing_folder 1 "no/such/folder/x.tanim: folder .*no/such/folder does not exist" generate wave -o ${H}/no/such/folder/x.tanim)
tsah_expect_error(hard.out.is_folder 1 "folder.tanim: is a folder; expected a file name" generate wave -o ${H}/folder.tanim)
file(MAKE_DIRECTORY ${H}/folder.tanim)
string(REPEAT "n" 260 LONG)
tsah_expect_error(hard.out.name_too_long 1 "${LONG}.tanim: file name too long" generate wave -o ${H}/${LONG}.tanim --triangles 10 --frames 2)
string(REPEAT "l" 244 LEGAL)  # 250 characters with .tanim: legal, and the temporary name must fit too
add_test(NAME hard.out.long_legal_name COMMAND tsah generate wave -o ${H}/${LEGAL}.tanim --triangles 10 --frames 2)
tsah_expect_error(hard.out.export_file 2 "a.tanim exists and is not a folder" export ${H}/a.tbvh ${A} -o ${A})
tsah_hard_fixture(hard.out.export_file hard_tree)

# ---- 6. Memory statements before large allocations ---------------------------------------------------
add_test(NAME hard.setup.large COMMAND tsah generate wave -o ${H}/large.tanim --triangles 200000 --frames 2)
set_tests_properties(hard.setup.large PROPERTIES FIXTURES_SETUP hard_large)
tsah_expect_error(hard.memory.resample 1 "wave: 1000000 frames would need [0-9]+ MiB, more than the [0-9]+ MiB of memory available" resample ${H}/large.tanim -o ${H}/never.tanim --frames 1000000)
tsah_hard_fixture(hard.memory.resample hard_large)

# Tests that get as far as loading the animation or the tree need the fixtures.
foreach(t hard.out.tree_not_tbvh hard.out.resample_not_tanim hard.fps_nan)
  tsah_hard_fixture(${t} hard_anim)
endforeach()

# ---- Determinism: the same seed and thread count give byte-identical trees, for every method ------
foreach(variant "tsah;mh" "tsah;random" "tsah;batch" "sah0;mh" "sahstar;mh")
  list(GET variant 0 method)
  list(GET variant 1 selection)
  set(tag ${method}_${selection})
  foreach(run 1 2)
    add_test(NAME hard.det.${tag}.${run}
             COMMAND tsah optimize ${A} -o ${H}/det_${tag}_${run}.tbvh --method ${method} --selection ${selection}
                     --seed 7 --threads 2 --frames 3 --eval-frames 3)
    set_tests_properties(hard.det.${tag}.${run} PROPERTIES FIXTURES_REQUIRED hard_anim FIXTURES_SETUP det_${tag})
  endforeach()
  # The build time field differs between runs; everything else (tree, options, checksum of the
  # tree part) must not: compare the files with that field masked by tsah info --json of both.
  add_test(NAME hard.det.${tag}
           COMMAND ${CMAKE_COMMAND} -DA=${H}/det_${tag}_1.tbvh -DB=${H}/det_${tag}_2.tbvh
                   -P ${PROJECT_SOURCE_DIR}/tests/support/compare_trees.cmake)
  set_tests_properties(hard.det.${tag} PROPERTIES FIXTURES_REQUIRED det_${tag})
endforeach()
