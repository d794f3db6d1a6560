# Warnings live on one INTERFACE target that every isotouch target links.
add_library(isotouch_warnings INTERFACE)
add_library(isotouch::warnings ALIAS isotouch_warnings)
target_compile_options(isotouch_warnings INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion -Wno-missing-field-initializers>)
