# isotouch replay on the committed regression recording (tests/data/recordings/sphere-edits.rec:
# the sphere with a carve timeline, a stroke at the VHIP, an undo and the button drill) and on
# copies of it broken on purpose, and on copies whose scene file changed or is gone. Each case checks the exit code and the message.
#   -DEXE=isotouch -DREC=sphere-edits.rec -DSCENE=sphere-edits.json -DOUT=work folder
file(REMOVE_RECURSE ${OUT})
file(MAKE_DIRECTORY ${OUT})

function(expect name rc regex)
  execute_process(COMMAND ${EXE} replay ${ARGN} --quiet RESULT_VARIABLE got OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT got EQUAL rc)
    message(FATAL_ERROR "${name}: exit ${got}, expected ${rc}\n${out}\n${err}")
  endif()
  if(NOT "${out}${err}" MATCHES "${regex}")
    message(FATAL_ERROR "${name}: output does not match '${regex}':\n${out}\n${err}")
  endif()
  message(STATUS "${name}: exit ${got} as expected")
endfunction()

file(READ ${REC} rec)
file(READ ${SCENE} scene)
# The edits the recording holds, from its end record (the drill's count follows the forces:
# a re-recording after an intended servo change may differ).
if(NOT rec MATCHES "{\"end\":true,\"ticks\":2403,\"edits\":([0-9]+)}")
  message(FATAL_ERROR "${REC}: no end record of 2403 ticks")
endif()
set(edits ${CMAKE_MATCH_1})

# 1. As recorded: every force identical, exit 0.
expect(identical 0 "replayed 2403 ticks, ${edits} edits.*max \\|dF\\| 0 N.*IDENTICAL" ${REC} --out ${OUT}/trace)
if(NOT EXISTS ${OUT}/trace/trace.csv)
  message(FATAL_ERROR "identical: no trace.csv in ${OUT}/trace")
endif()

# 2. One HIP moved (tick 1000, in contact under the drill): exit 1, the first difference at tick 1000.
string(REGEX REPLACE "(\"k\":1000,\"t\":[^,]*,\"hip\":\\[[^,]*,[^,]*,)[^]]*\\]" "\\10.0311]" moved "${rec}")
if(moved STREQUAL rec)
  message(FATAL_ERROR "tick 1000's HIP not found in ${REC}")
endif()
file(MAKE_DIRECTORY ${OUT}/moved)
file(WRITE ${OUT}/moved/sphere-edits.rec "${moved}")
file(WRITE ${OUT}/moved/sphere-edits.json "${scene}")
expect(moved_hip 1 "DIFFERENT: [0-9]+ of 2403 ticks differ; first at tick 1000 \\(t = 1 s\\)" ${OUT}/moved/sphere-edits.rec)

# 2b. A HIP of 1e300 hand-edited into a free-space tick (tick 20, the device at rest): the force
# and the VHIP stay as recorded, the replayed tick is a fault: exit 1, found at tick 20.
string(REGEX REPLACE "(\"k\":20,\"t\":[^,]*,\"hip\":\\[)[^,]*," "\\11e300," absurd "${rec}")
if(absurd STREQUAL rec)
  message(FATAL_ERROR "tick 20's HIP not found in ${REC}")
endif()
file(MAKE_DIRECTORY ${OUT}/absurd)
file(WRITE ${OUT}/absurd/sphere-edits.rec "${absurd}")
file(WRITE ${OUT}/absurd/sphere-edits.json "${scene}")
expect(absurd_hip 1 "DIFFERENT: [0-9]+ of 2403 ticks differ; first at tick 20 \\(t = 0.02 s\\) in the fault" ${OUT}/absurd/sphere-edits.rec)

# 3. The scene file changed since the recording, or is gone: the recording carries the scene's
# text and runs it, identical (exit 0).
file(MAKE_DIRECTORY ${OUT}/changed ${OUT}/alone)
file(WRITE ${OUT}/changed/sphere-edits.rec "${rec}")
file(WRITE ${OUT}/changed/sphere-edits.json "{\"isovalue\": 7}")
expect(changed_scene 0 "replayed 2403 ticks, ${edits} edits.*IDENTICAL" ${OUT}/changed/sphere-edits.rec)
file(WRITE ${OUT}/alone/sphere-edits.rec "${rec}")
expect(scene_gone 0 "replayed 2403 ticks, ${edits} edits.*IDENTICAL" ${OUT}/alone/sphere-edits.rec)

# 4. Truncated (the end record cut off): exit 2, said.
string(FIND "${rec}" "{\"end\"" at)
string(SUBSTRING "${rec}" 0 ${at} cut)
file(WRITE ${OUT}/changed/cut.rec "${cut}")
expect(truncated 2 "cut.rec: truncated after line [0-9]+ \\(2403 ticks, ${edits} edits read\\): no end record" ${OUT}/changed/cut.rec)

# 5. No such file: exit 2.
expect(missing 2 "no-such.rec: no such recording" ${OUT}/no-such.rec)
