# Compiler flags shared by every target of the project.
add_library(nao_flags INTERFACE)
target_compile_options(nao_flags INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  # Determinism: no fused multiply-add contraction, so results do not depend on what the
  # compiler chose to fuse (DESIGN section 9).
  -ffp-contract=off)
if(NAO_SANITIZE)
  target_compile_options(nao_flags INTERFACE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined)
  target_link_options(nao_flags INTERFACE -fsanitize=address,undefined)
endif()
