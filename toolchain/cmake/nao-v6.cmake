# CMake toolchain file for the NAO V6 (docs/embedded.md).
#
# The robot's CPU is an Intel Atom E3845 (Bay Trail, "silvermont" cores: x86-64 with SSE4.2,
# no AVX, no FMA). Its OS is older than this Debian 12 build host, so the executables are linked
# statically: nothing of the host's glibc, libstdc++, ODE or TinyXML has to exist on the robot.
# Same architecture as the host, so the build runs here too (and the tests run it).
#
#   cmake --preset nao && cmake --build build-nao      # or: toolchain/nao build --preset nao
#
# What it sets:
#   -march=silvermont -mtune=silvermont  the Atom's instruction set; the compiler emits no AVX/FMA
#   NAO_POLICY_HAVE_AVX2=0               leaves out the policy's AVX2 kernel (target("avx2")
#                                        functions would put ymm instructions into the binary):
#                                        the SSE kernel only, bit-identical to it
#   NAO_LOLA_IO_THREAD_DEFAULT=1         nao_rt --robot lola answers on its I/O thread unless
#                                        --lola-one-thread (the Atom's tick may exceed LoLA's 12 ms)
#   -ffp-contract=off                    stays (cmake/NaoFlags.cmake, every build): no fused
#                                        multiply-add, results do not depend on the target
#   NAO_STATIC, NAO_URDF_READER=tinyxml  one static executable (libraries found as lib*.a:
#                                        cmake/NaoDependencies.cmake); urdfdom has no static archive in
#                                        Debian, so the URDF is read by TinyXML (urdf_reader.hpp)
#   NAO_RUNTIME_ONLY                     nao_rt, nao_lola_sim, nao_attn_tail (+ nao_codegen for the
#                                        compiled-in model): no toolchain, libtorch, tests, bench
#   NAO_MODEL_PRECISION=fp32             the compiled-in weights as model.bin lays them out (the
#                                        native build's default is fp32-packed)
set(NAO_TARGET_CPU_FLAGS "-march=silvermont -mtune=silvermont -DNAO_POLICY_HAVE_AVX2=0 -DNAO_LOLA_IO_THREAD_DEFAULT=1")
set(CMAKE_C_FLAGS_INIT "${NAO_TARGET_CPU_FLAGS}")
set(CMAKE_CXX_FLAGS_INIT "${NAO_TARGET_CPU_FLAGS}")
set(CMAKE_ASM_FLAGS_INIT "-march=silvermont")

set(NAO_STATIC ON CACHE BOOL "Link the executables statically" FORCE)
set(NAO_URDF_READER tinyxml CACHE STRING "URDF reader of nao_runtime" FORCE)
set(NAO_RUNTIME_ONLY ON CACHE BOOL "Build only the runtime executables" FORCE)
# fp32, not the native build's fp32-packed: the SSE kernel runs as fast from model.bin's layout
# (bench/results/policy.txt), and the binary copied to the robot stays 24 MB smaller.
set(NAO_MODEL_PRECISION fp32 CACHE STRING "Precision of the compiled-in model's weights")
