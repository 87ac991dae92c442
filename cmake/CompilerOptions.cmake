# Warning and sanitizer flags shared by every Sandtable target (through sandtable_options).
add_library(sandtable_options INTERFACE)
add_library(sandtable::options ALIAS sandtable_options)
# -Wshadow=local is GCC's alone (clang warns that it does not know it, on every file).
target_compile_options(sandtable_options INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic>
  $<$<CXX_COMPILER_ID:GNU>:-Wshadow=local>
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wnon-virtual-dtor -Wno-missing-field-initializers>)
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
# Debug information goes to a .dwo file beside each object (split DWARF) instead of being copied
# into every static library and every test executable that links it: with it inline the build
# folder grew past 12 GB (98 % of each executable was .debug_*) and filled CI's disk. gdb reads
# the .dwo files from the build folder.
# What split DWARF leaves in an executable (GCC 12 always adds its name index, .debug_gnu_pub*,
# ~140 MB in sandtable-node) is compressed when linking (zlib; gdb reads it).
option(SANDTABLE_SPLIT_DWARF "Keep debug information in .dwo files beside the objects" ON)
if(SANDTABLE_SPLIT_DWARF AND CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
  add_compile_options($<$<AND:$<CONFIG:RelWithDebInfo,Debug>,$<COMPILE_LANGUAGE:C,CXX>>:-gsplit-dwarf>)
  add_link_options($<$<CONFIG:RelWithDebInfo,Debug>:LINKER:--compress-debug-sections=zlib>)
endif()
