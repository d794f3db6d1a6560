# header_internals: which project headers a program that includes only the public header
# (isotouch/isotouch.h) or session/live_session.h gets, read from the compiler's own list
# (-M, what the preprocessor opened). The live session's internals (its rings, its seqlock)
# stay in live_session.cpp (LiveSession::Impl): none of them may reach a consumer.
# -DCXX=compiler -DINCLUDE=build/include -DGENERATED=build/generated -DWORK=scratch folder
file(MAKE_DIRECTORY ${WORK})
set(internal servo/spsc_ring.h servo/latest_value.h)
foreach(header isotouch/isotouch.h isotouch/session/live_session.h)
  file(WRITE ${WORK}/tu.cpp "#include \"${header}\"\n")
  execute_process(COMMAND ${CXX} -std=c++20 -I${INCLUDE} -I${GENERATED} -M ${WORK}/tu.cpp
                  RESULT_VARIABLE rc OUTPUT_VARIABLE deps ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "header_internals: ${CXX} -M on ${header} failed (${rc}): ${err}")
  endif()
  foreach(i ${internal})
    string(FIND "${deps}" "isotouch/${i}" at)
    if(NOT at EQUAL -1)
      message(FATAL_ERROR "header_internals: ${header} pulls in the internal isotouch/${i}")
    endif()
  endforeach()
  # The check sees headers at all: the header itself is in its own list.
  string(FIND "${deps}" "${header}" self)
  if(self EQUAL -1)
    message(FATAL_ERROR "header_internals: ${header} not in its own -M list (the check reads nothing)")
  endif()
endforeach()
message("PASS header_internals")
