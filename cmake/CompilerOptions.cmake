# Warning and sanitizer flags shared by every Sandtable target (through sandtable_options).
add_library(sandtable_options INTERFACE)
add_library(sandtable::options ALIAS sandtable_options)
target_compile_options(sandtable_options INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wshadow=local -Wnon-virtual-dtor
    -Wno-missing-field-initializers>)
if(SANDTABLE_WERROR)
  target_compile_options(sandtable_options INTERFACE $<$<CXX_COMPILER_ID:GNU,Clang>:-Werror>)
endif()
if(SANDTABLE_ENABLE_ASAN)
  target_compile_options(sandtable_options INTERFACE
    -fsanitize=address,undefined -fno-omit-frame-pointer)
  target_link_options(sandtable_options INTERFACE -fsanitize=address,undefined)
endif()
find_program(SANDTABLE_CCACHE ccache)
if(SANDTABLE_CCACHE)
  set(CMAKE_CXX_COMPILER_LAUNCHER "${SANDTABLE_CCACHE}")
endif()
