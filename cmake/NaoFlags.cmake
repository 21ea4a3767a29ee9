# Compiler flags shared by every target of the project.
add_library(nao_flags INTERFACE)
target_compile_options(nao_flags INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  # Determinism: no fused multiply-add contraction, so results do not depend on what the
  # compiler chose to fuse.
  -ffp-contract=off)
if(NAO_STATIC)
  # The robot build: one self-contained executable (glibc, libstdc++, ODE, TinyXML inside), so it
  # runs on the NAO's own OS whatever its library versions (docs/embedded.md).
  target_link_options(nao_flags INTERFACE -static)
endif()
if(NAO_SANITIZE)
  target_compile_options(nao_flags INTERFACE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined)
  target_link_options(nao_flags INTERFACE -fsanitize=address,undefined)
endif()
if(NAO_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "NAO_FUZZ needs clang's libFuzzer: configure with the preset fuzz "
                        "(CMAKE_CXX_COMPILER=clang++; Debian packages clang and libclang-rt-14-dev)")
  endif()
  # Every object gets libFuzzer's coverage hooks and the sanitizers; the fuzz executables add
  # -fsanitize=fuzzer at link time (tests/fuzz/CMakeLists.txt), which brings libFuzzer's main.
  target_compile_options(nao_flags INTERFACE -fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined -g)
  target_link_options(nao_flags INTERFACE -fsanitize=address,undefined)
endif()
