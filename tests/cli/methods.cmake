# Method names: tsah<k> with k beyond the objective's limit (Objective::kMaxK = 16) is a usage error
# of `tsah evaluate --methods` (and of Python's method and methods), not a run with C_i^k near overflow.
# tsah_expect_error and the a.tanim fixture: hardening.cmake.
tsah_expect_error(cli.methods.k_too_large 2 "^tsah: --methods: method 'tsah99': the T-SAH exponent k must be in 0\\.\\.16"
                  evaluate ${TSAH_CLI_WORK}/hard/a.tanim --methods sah0,tsah99 --eval-frames 2)
tsah_hard_fixture(cli.methods.k_too_large hard_anim)
