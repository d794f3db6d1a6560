# ASan+UBSan for the debug preset (ISOTOUCH_SANITIZE=ON).
add_library(isotouch_sanitizers INTERFACE)
add_library(isotouch::sanitizers ALIAS isotouch_sanitizers)
if(ISOTOUCH_SANITIZE)
  target_compile_options(isotouch_sanitizers INTERFACE
    -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  target_link_options(isotouch_sanitizers INTERFACE -fsanitize=address,undefined)
endif()
if(ISOTOUCH_TSAN)
  target_compile_options(isotouch_sanitizers INTERFACE -fsanitize=thread -fno-omit-frame-pointer)
  target_link_options(isotouch_sanitizers INTERFACE -fsanitize=thread)
endif()
