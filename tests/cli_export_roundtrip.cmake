# What `isotouch export` writes goes wherever a volume does: the head CT exported to .vdb,
# .nrrd, .mha and .nii.gz is checked by `check` (GPU vs CPU), rendered by `render` and run by
# `run` through a scene naming it; a .mhd output is refused with the reason.
#   -DEXE=isotouch -DDATA=data folder -DOUT=work folder
file(REMOVE_RECURSE ${OUT})
file(MAKE_DIRECTORY ${OUT})
function(expect name rc regex)
  execute_process(COMMAND ${EXE} ${ARGN} RESULT_VARIABLE got OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT got EQUAL rc)
    message(FATAL_ERROR "${name}: exit ${got}, expected ${rc}\n${out}\n${err}")
  endif()
  if(NOT "${out}${err}" MATCHES "${regex}")
    message(FATAL_ERROR "${name}: output does not match '${regex}':\n${out}\n${err}")
  endif()
  message(STATUS "${name}: ok")
endfunction()
set(head ${DATA}/ct-head-headsq/headsq_64x64x93_int16.mhd)
expect(export 0 "wrote +${OUT}/head.vdb.*wrote +${OUT}/head.nrrd" export ${head} --vdb ${OUT}/head.vdb --volume ${OUT}/head.nrrd)
expect(export_mha 0 "wrote +${OUT}/head.mha" export ${head} --volume ${OUT}/head.mha)
expect(export_nii_gz 0 "wrote +${OUT}/head.nii.gz" export ${OUT}/head.vdb --volume ${OUT}/head.nii.gz)
expect(export_mhd_refused 2 "head.mhd: the name must end in .mha.*use .mha" export ${head} --volume ${OUT}/head.mhd)
foreach(f head.vdb head.nrrd head.mha head.nii.gz)
  expect(check_${f} 0 "\\(64x64x93, .*PASS" check ${OUT}/${f})
endforeach()
file(WRITE ${OUT}/vdb-scene.json "{\"name\": \"vdb-scene\", \"volume\": {\"path\": \"head.vdb\"}, \"isovalue\": 1150, \"inside\": \"above\",
  \"script\": {\"ray_origin_frac\": [1.2, 0.5, 0.12], \"ray_direction\": [-1, 0, 0], \"hold_s\": 0.05, \"stroke_length_m\": 0.005},
  \"outputs\": {\"plots\": false}}")
expect(render_vdb 0 "render: wrote ${OUT}/vdb.png" render ${OUT}/vdb-scene.json --out ${OUT}/vdb.png --width 64 --height 64)
expect(run_vdb 0 "contact +[1-9][0-9]* ticks" run ${OUT}/vdb-scene.json --out ${OUT}/run --quiet)
# summary.json names the reader that read the file (OpenVDB), the first one in brackets.
file(GLOB_RECURSE summary ${OUT}/run/summary.json)
file(READ "${summary}" text)
if(NOT text MATCHES "\"reader\": \"openvdb:FloatGrid \\(converted from itk:MetaImageIO\\)\"")
  message(FATAL_ERROR "run_vdb: ${summary} does not name the OpenVDB reader:\n${text}")
endif()
