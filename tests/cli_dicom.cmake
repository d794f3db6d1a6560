# A DICOM series folder on the command line: `isotouch check FOLDER` reads the shipped chest
# series (512x512x64, GDCM, spacing from the slices) and passes; an empty folder and a copy
# of the series with one slice removed from the middle exit 1 naming the folder and the fault.
# Usage: cmake -DEXE=isotouch -DSERIES=data/ct-chest-lungdx-a0001/dicom-5mm -DOUT=dir -P cli_dicom.cmake
function(expect name rc regex)
  execute_process(COMMAND ${EXE} ${ARGN} RESULT_VARIABLE got OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 300)
  message("== ${name}: exit ${got}\n${out}${err}")
  if(NOT "${got}" STREQUAL "${rc}")
    message(FATAL_ERROR "${name}: exit ${got}, want ${rc}")
  endif()
  if(NOT "${out}${err}" MATCHES "${regex}")
    message(FATAL_ERROR "${name}: output does not match '${regex}'")
  endif()
endfunction()

file(REMOVE_RECURSE ${OUT})
file(MAKE_DIRECTORY ${OUT}/empty ${OUT}/missing)

expect(series 0 "volume +${SERIES} \\(512x512x64, short, itk:GDCMImageIO\\).*spacing +0\\.8418 x 0\\.8418 x 5 mm.*orientation +LPS.*corners +voxel \\(0,0,0\\) at \\(-228, -93\\.06, -439\\) mm.*values +\\[-1024, [0-9]+\\].*PASS"
       check ${SERIES})

expect(empty 1 "isotouch: error: ${OUT}/empty: no DICOM files: the folder holds no files" check ${OUT}/empty)

file(GLOB slices ${SERIES}/*.dcm)
foreach(s ${slices})
  get_filename_component(n ${s} NAME)
  if(NOT n STREQUAL "1-33.dcm")
    file(COPY ${s} DESTINATION ${OUT}/missing)
  endif()
endforeach()
expect(missing_slice 1 "isotouch: error: ${OUT}/missing: DICOM series [0-9.]+: a slice is missing between 1-34\\.dcm \\(at -289 mm\\) and 1-32\\.dcm \\(at -279 mm\\): they are 10 mm apart"
       check ${OUT}/missing)
message("PASS cli_dicom")
