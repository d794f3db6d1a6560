# The installed package, as a consumer sees it: `cmake --install` of the build tree into a
# fresh prefix, then examples/embed configured against that prefix alone (its own build
# folder, -DCMAKE_PREFIX_PATH=PREFIX, no package registry), built and run on the head CT
# (contact force, one carve read by the servo, the session's recording).
# Also: every installed header's "isotouch/..." includes resolve inside the prefix; a consumer
# of one component finds only that component's packages; a consumer of servo and live alone
# neither finds nor loads ITK or OpenVDB; the pkg-config file's flags compile
# the example; the archives are position-independent.
#   cmake -DBUILD=DIR -DSOURCE=DIR -DWORK=DIR -DVOLUME=FILE -P install_embed.cmake
foreach(v BUILD SOURCE WORK VOLUME)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "install_embed: -D${v}= is required")
  endif()
endforeach()
set(prefix ${WORK}/prefix)
set(embed ${WORK}/embed-build)
file(REMOVE_RECURSE ${WORK})
file(MAKE_DIRECTORY ${WORK})

function(run_step name)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "install_embed: ${name} failed (exit ${rc}):\n${out}\n${err}")
  endif()
  set(step_out "${out}" PARENT_SCOPE)
  set(step_err "${err}" PARENT_SCOPE)
endfunction()

# 1. Install (the build tree's artifacts; nothing is compiled).
run_step("cmake --install" ${CMAKE_COMMAND} --install ${BUILD} --prefix ${prefix})
foreach(f include/isotouch/isotouch.h include/isotouch/version.h lib/cmake/isotouch/isotouchConfig.cmake
          lib/cmake/isotouch/isotouchConfigVersion.cmake bin/isotouch bin/isotouch-devemu)
  if(NOT EXISTS ${prefix}/${f})
    message(FATAL_ERROR "install_embed: ${prefix}/${f} was not installed")
  endif()
endforeach()

# 2. Every quoted include of an installed header is an installed "isotouch/..." header.
file(GLOB_RECURSE headers RELATIVE ${prefix}/include ${prefix}/include/*.h)
list(LENGTH headers n_headers)
set(n_includes 0)
foreach(h IN LISTS headers)
  file(STRINGS ${prefix}/include/${h} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
  foreach(line IN LISTS lines)
    string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*" "\\1" inc "${line}")
    math(EXPR n_includes "${n_includes} + 1")
    if(NOT inc MATCHES "^isotouch/")
      message(FATAL_ERROR "install_embed: ${h} includes \"${inc}\": a bare name on the consumer's include path")
    endif()
    if(NOT EXISTS ${prefix}/include/${inc})
      message(FATAL_ERROR "install_embed: ${h} includes \"${inc}\", which is not installed")
    endif()
  endforeach()
endforeach()
message(STATUS "install_embed: ${n_headers} headers installed, their ${n_includes} project includes all resolve")

# 3. The example against the prefix alone.
set(launcher)
find_program(CCACHE ccache)
if(CCACHE)
  set(launcher -DCMAKE_CXX_COMPILER_LAUNCHER=${CCACHE})
endif()
run_step("configuring examples/embed" ${CMAKE_COMMAND} -S ${SOURCE}/examples/embed -B ${embed} -G Ninja
  -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF ${launcher})
file(STRINGS ${embed}/CMakeCache.txt found_dir REGEX "^isotouch_DIR:")
if(NOT found_dir STREQUAL "isotouch_DIR:PATH=${prefix}/lib/cmake/isotouch")
  message(FATAL_ERROR "install_embed: the example found isotouch elsewhere: ${found_dir}")
endif()
# ITK's config finds GDCM, whose targets file names each command-line tool that is not
# installed: the package config finds ITK with status messages off (isotouchConfig.cmake.in).
string(REGEX MATCHALL "The imported target \"gdcm[^\"]*\"" gdcm_notes "${step_out}${step_err}")
if(gdcm_notes)
  list(LENGTH gdcm_notes n_gdcm_notes)
  message(FATAL_ERROR "install_embed: the example's configure printed ${n_gdcm_notes} GDCM notes: ${gdcm_notes}")
endif()
run_step("building examples/embed" ${CMAKE_COMMAND} --build ${embed})
set(recording ${WORK}/embed.rec)
execute_process(COMMAND ${embed}/isotouch-embed ${VOLUME} 1150 ${recording} RESULT_VARIABLE rc OUTPUT_VARIABLE out
                ERROR_VARIABLE err)
message(STATUS "isotouch-embed (exit ${rc}):\n${out}${err}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "install_embed: isotouch-embed exited ${rc}")
endif()
# Contact: a force of at least 0.1 N; the carve read by a later tick.
if(NOT out MATCHES "contact +at tick [0-9]+: \\|F\\| = ([0-9]+\\.[0-9]+) N")
  message(FATAL_ERROR "install_embed: no contact line in the output")
endif()
if(CMAKE_MATCH_1 LESS 0.1)
  message(FATAL_ERROR "install_embed: |F| = ${CMAKE_MATCH_1} N at contact, expected > 0.1 N")
endif()
if(NOT out MATCHES "carved +at tick [0-9]+: \\|F\\| = [0-9]+\\.[0-9]+ N.*snapshot [2-9]" OR
   NOT out MATCHES "1 edits applied")
  message(FATAL_ERROR "install_embed: the carve was not applied and read")
endif()
# A volume that is not there: exit 1, one message naming the file.
execute_process(COMMAND ${embed}/isotouch-embed ${WORK}/no-such-volume.mhd RESULT_VARIABLE bad_rc
                OUTPUT_VARIABLE bad_out ERROR_VARIABLE bad_err)
if(NOT bad_rc EQUAL 1 OR NOT bad_err MATCHES "^isotouch-embed: [^\n]*no-such-volume\\.mhd")
  message(FATAL_ERROR "install_embed: a missing volume gave exit ${bad_rc}, stderr: ${bad_err}")
endif()

# The installed program's version is the one the example's headers carry.
string(REGEX MATCH "\\(isotouch ([0-9]+\\.[0-9]+\\.[0-9]+)\\)" _ "${out}")
set(header_version ${CMAKE_MATCH_1})
run_step("isotouch --version" ${prefix}/bin/isotouch --version)
if(header_version STREQUAL "" OR NOT step_out STREQUAL "isotouch ${header_version}\n")
  message(FATAL_ERROR "install_embed: the installed isotouch says \"${step_out}\", the installed headers \"${header_version}\"")
endif()

# The recording, read as a file: one line per tick the session counted, one carve.
if(NOT out MATCHES "session +([0-9]+) ticks")
  message(FATAL_ERROR "install_embed: no session line in the output")
endif()
set(ticks ${CMAKE_MATCH_1})
if(NOT EXISTS ${recording})
  message(FATAL_ERROR "install_embed: ${recording} was not written")
endif()
file(STRINGS ${recording} tick_lines REGEX "^{\"k\":")
file(STRINGS ${recording} carve_lines REGEX "^{\"edit\":\"brush\".*\"kind\":\"carve\"")
list(LENGTH tick_lines n_tick_lines)
list(LENGTH carve_lines n_carve_lines)
if(NOT n_tick_lines EQUAL ticks OR NOT n_carve_lines EQUAL 1)
  message(FATAL_ERROR "install_embed: ${recording} holds ${n_tick_lines} ticks and ${n_carve_lines} carves; "
                      "the session ran ${ticks} ticks and one carve")
endif()
message(STATUS "install_embed: ${recording}: ${n_tick_lines} ticks, 1 carve")

# 4. A component alone: find_package(isotouch COMPONENTS servo) finds Threads only (no Vulkan,
# ITK or OpenVDB in the consumer's cache), and a renderer links with isotouch::servo alone.
set(servo_src ${WORK}/servo-only)
file(WRITE ${servo_src}/CMakeLists.txt [=[
cmake_minimum_required(VERSION 3.22)
project(servo_only LANGUAGES C CXX)
find_package(isotouch CONFIG REQUIRED COMPONENTS servo)
add_executable(servo-only main.cpp)
target_compile_features(servo-only PRIVATE cxx_std_20)
target_link_libraries(servo-only PRIVATE isotouch::servo)
]=])
file(WRITE ${servo_src}/main.cpp [=[
#include <cstdio>
#include "isotouch/servo/hri.h"
int main() {
  isotouch::servo::HriRenderer hri(isotouch::servo::HriParams{});
  std::printf("renderer %s\n", hri.name());
}
]=])
run_step("configuring a servo-only consumer" ${CMAKE_COMMAND} -S ${servo_src} -B ${WORK}/servo-only-build -G Ninja
  -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF ${launcher})
file(STRINGS ${WORK}/servo-only-build/CMakeCache.txt heavy REGEX "^(ITK_DIR|Vulkan_LIBRARY|OpenVDB_[A-Za-z_]*|assimp_DIR):")
if(heavy)
  message(FATAL_ERROR "install_embed: COMPONENTS servo found more than it needs: ${heavy}")
endif()
run_step("building a servo-only consumer" ${CMAKE_COMMAND} --build ${WORK}/servo-only-build)
run_step("running the servo-only consumer" ${WORK}/servo-only-build/servo-only)
if(NOT step_out MATCHES "^renderer [A-Za-z]")
  message(FATAL_ERROR "install_embed: the servo-only consumer printed: ${step_out}")
endif()
message(STATUS "install_embed: COMPONENTS servo: Threads only; ${step_out}")

# 4a. The live path alone: a program that links isotouch::servo and isotouch::live (a sphere
# volume made in memory, the live session on a simulated device until contact) finds neither
# Vulkan, ITK nor OpenVDB (nor assimp, OpenIGTLink, hidapi) at configure, and none of their
# shared libraries is loaded by the program (ldd, what the dynamic loader resolves for the
# binary): the session's GPU parts are in isotouch::session_gpu (session/gpu_parts.h).
set(live_src ${WORK}/live-only)
file(WRITE ${live_src}/CMakeLists.txt [=[
cmake_minimum_required(VERSION 3.22)
project(live_only LANGUAGES CXX)
find_package(isotouch CONFIG REQUIRED COMPONENTS servo live)
add_executable(live-only main.cpp)
target_compile_features(live-only PRIVATE cxx_std_20)
target_link_libraries(live-only PRIVATE isotouch::servo isotouch::live)
]=])
file(WRITE ${live_src}/main.cpp [=[
#include <chrono>
#include <cstdio>
#include <thread>
#include "isotouch/engine/synthetic.h"
#include "isotouch/session/session.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"
#include "isotouch/sim/sim_device_io.h"
namespace it = isotouch;
int main() {
  // A sphere of radius 20 mm (signed distance in mm, positive inside), felt at isovalue 0.
  it::engine::Volume volume = it::engine::make_sphere({64, 64, 64}, 1e-3, 20.0);
  it::servo::WorkspaceTransform world_T_device;
  world_T_device.translation_m = volume.grid.centre_m();
  it::session::SessionOptions options;
  options.field.iso = it::core::Isosurface{0.0, it::core::InsideIs::kAbove};
  options.field.background = float(options.field.iso.outside_value(volume.min_value, volume.max_value));
  options.hri.tau = 0.0;
  options.hri.inside = it::core::InsideIs::kAbove;
  it::session::Opened opened = it::session::Session::open(std::move(volume), options);
  if (!opened) { std::fprintf(stderr, "live-only: %s\n", opened.error.c_str()); return 1; }
  it::session::Session& s = *opened.session;
  const it::sim::TouchScript script = it::sim::make_touch_script(*s.edits().current(), options.hri, {});
  it::sim::SimDevice device({}, world_T_device.to_device(script.waypoints.front().pos_m));
  it::sim::SimDeviceIO io(device, script, 1.0 / options.hri.rate_hz, world_T_device);
  it::session::LiveSessionConfig config;
  config.servo.rate_hz = options.hri.rate_hz;
  config.servo.sched_fifo = config.servo.pin_cpu = config.servo.lock_memory = false;
  config.servo.world_T_device = world_T_device;
  if (it::session::SetupResult r = s.attach(io, config); !r) { std::fprintf(stderr, "live-only: %s\n", r.error.c_str()); return 1; }
  it::session::LiveSession& live = *s.live();
  live.start();
  // The hand is pressed in by the stroke's start (script time: the servo's ticks, which a
  // loaded machine delays), 1 s of ticks more; 60 s of wall time for a servo that stalls.
  const long last_tick = long((script.t_stroke + 1.0) * options.hri.rate_hz);
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  it::session::Observed o = live.observe();
  while (!(o.contact && it::core::norm(o.force_n) > 0.5) && o.tick < last_tick &&
         std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    o = live.observe();
  }
  it::session::stop_or_end_process(live, "live-only");
  std::printf("live-only contact %d |F| = %.4f N at tick %ld\n", int(o.contact), it::core::norm(o.force_n), o.tick);
  return o.contact ? 0 : 3;
}
]=])
run_step("configuring a servo + live consumer" ${CMAKE_COMMAND} -S ${live_src} -B ${WORK}/live-only-build -G Ninja
  -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF ${launcher})
file(STRINGS ${WORK}/live-only-build/CMakeCache.txt heavy
     REGEX "^(Vulkan_LIBRARY|ITK_DIR|GDCM_DIR|OpenVDB_[A-Za-z_]*|assimp_DIR|OpenIGTLink_DIR|HIDAPI_[A-Za-z_]*):")
if(heavy)
  message(FATAL_ERROR "install_embed: COMPONENTS servo live found what the live path does not need: ${heavy}")
endif()
run_step("building a servo + live consumer" ${CMAKE_COMMAND} --build ${WORK}/live-only-build)
run_step("running the servo + live consumer" ${WORK}/live-only-build/live-only)
if(NOT step_out MATCHES "^live-only contact 1 \\|F\\| = [0-9.]+ N")
  message(FATAL_ERROR "install_embed: the servo + live consumer printed: ${step_out}")
endif()
set(live_out "${step_out}")
run_step("ldd of the servo + live consumer" ldd ${WORK}/live-only-build/live-only)
string(REGEX MATCHALL "lib(vulkan|ITK|itk|gdcm|teem|openvdb|assimp|OpenIGTLink|hidapi)[^ \t\n]*" loaded "${step_out}")
if(loaded)
  message(FATAL_ERROR "install_embed: the servo + live consumer loads ${loaded}:\n${step_out}")
endif()
string(REGEX MATCHALL "\n" ldd_lines "${step_out}")
list(LENGTH ldd_lines n_ldd)
# The isotouch archives on its link line (what the build linked, for the log).
file(STRINGS ${WORK}/live-only-build/build.ninja link_line REGEX "^ +LINK_LIBRARIES = ")
string(REGEX MATCHALL "libisotouch_[a-z_]+\\.a" archives_linked "${link_line}")
list(REMOVE_DUPLICATES archives_linked)
message(STATUS "install_embed: COMPONENTS servo live: no Vulkan, ITK, OpenVDB, assimp, OpenIGTLink or hidapi found "
               "or loaded (${n_ldd} ldd lines); links ${archives_linked}; ${live_out}")

# 4b. A consumer that enables CXX alone (project(x LANGUAGES CXX)) and asks for everything:
# ITK's HDF5 needs C, which the package config enables (before, FindHDF5's try_compile
# failed: "works only for enabled languages"); the consumer's cache then names a C compiler.
# Called inside a function, where C cannot be enabled: one clear message at find_package.
set(cxx_src ${WORK}/cxx-only)
file(WRITE ${cxx_src}/CMakeLists.txt [=[
cmake_minimum_required(VERSION 3.22)
project(cxx_only LANGUAGES CXX)
if(FIND_IN_FUNCTION)
  function(find_isotouch)
    find_package(isotouch CONFIG REQUIRED)
  endfunction()
  find_isotouch()
else()
  find_package(isotouch CONFIG REQUIRED)
endif()
]=])
run_step("configuring a CXX-only consumer" ${CMAKE_COMMAND} -S ${cxx_src} -B ${WORK}/cxx-only-build -G Ninja
  -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF)
file(STRINGS ${WORK}/cxx-only-build/CMakeCache.txt found_itk REGEX "^ITK_DIR:PATH=.+")
if(NOT found_itk)
  message(FATAL_ERROR "install_embed: the CXX-only consumer's configure did not find ITK")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -S ${cxx_src} -B ${WORK}/cxx-only-fn-build -G Ninja -DFIND_IN_FUNCTION=ON
  -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF
  RESULT_VARIABLE fn_rc OUTPUT_VARIABLE fn_out ERROR_VARIABLE fn_err)
if(fn_rc EQUAL 0 OR NOT fn_err MATCHES "isotouch: ITK \\(isotouch::volume_io\\) needs the C language")
  message(FATAL_ERROR "install_embed: find_package(isotouch) in a function of a CXX-only project gave exit ${fn_rc}:\n${fn_err}")
endif()
message(STATUS "install_embed: a CXX-only consumer configures (C enabled by the package); in a function: one message")

# 5. pkg-config: the flags compile the example (which is not linked this way: ITK and OpenVDB
# have no .pc file), and build and link the servo-only program.
find_program(PKG_CONFIG pkg-config)
if(PKG_CONFIG)
  set(ENV{PKG_CONFIG_PATH} ${prefix}/lib/pkgconfig)
  run_step("pkg-config --cflags isotouch" ${PKG_CONFIG} --cflags isotouch)
  separate_arguments(cflags UNIX_COMMAND "${step_out}")
  run_step("pkg-config --libs --static isotouch" ${PKG_CONFIG} --libs --static isotouch)
  separate_arguments(ldflags UNIX_COMMAND "${step_out}")
  string(REGEX MATCHALL "-lisotouch_[a-z_]+" libs "${step_out}")
  foreach(l IN LISTS libs)
    string(REPLACE "-l" "lib" a "${l}.a")
    if(NOT EXISTS ${prefix}/lib/${a})
      message(FATAL_ERROR "install_embed: isotouch.pc names ${l}, but ${prefix}/lib/${a} is not installed")
    endif()
  endforeach()
  find_program(CXX NAMES c++ g++ REQUIRED)
  run_step("compiling examples/embed with pkg-config's flags" ${CXX} -std=c++20 -fsyntax-only ${cflags}
    ${SOURCE}/examples/embed/main.cpp)
  run_step("building the servo-only program with pkg-config's flags" ${CXX} -std=c++20 ${cflags}
    ${servo_src}/main.cpp -o ${WORK}/servo-only-pc ${ldflags})
  run_step("running the servo-only program built with pkg-config" ${WORK}/servo-only-pc)
  if(NOT step_out MATCHES "^renderer [A-Za-z]")
    message(FATAL_ERROR "install_embed: the servo-only program (pkg-config) printed: ${step_out}")
  endif()
  message(STATUS "install_embed: pkg-config: ${cflags}; the example compiles, the servo-only program links and runs")
endif()
# 6. Position-independent archives (a Python module links them): every installed one, whole,
# into one shared object (an object built without -fPIC refuses: "recompile with -fPIC").
file(GLOB archives ${prefix}/lib/libisotouch_*.a)
find_program(CXX NAMES c++ g++ REQUIRED)
run_step("linking the installed archives into a shared object" ${CXX} -shared -o ${WORK}/all.so
  -Wl,--whole-archive ${archives} -Wl,--no-whole-archive)
list(LENGTH archives n_archives)
message(STATUS "install_embed: ${n_archives} archives link into a shared object")
message(STATUS "PASS install_embed")
