# Bad input on the command line: each case must exit non-zero (or as stated)
# quickly, with a message that names the file, the field and the value.
# Usage: cmake -DEXE=isotouch -DOUT=dir -DDATA=data-dir -P cli_bad_input.cmake
file(REMOVE_RECURSE ${OUT})
file(MAKE_DIRECTORY ${OUT})
set(failures "")

# expect(<name> <exit code> <regex> <args...>): run EXE args, check the code and the output.
function(expect name want regex)
  execute_process(COMMAND ${EXE} ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err
                  TIMEOUT 60)
  set(all "${out}${err}")
  if(NOT "${rc}" STREQUAL "${want}")
    set(failures "${failures}\n[${name}] exit ${rc}, want ${want}:\n${all}" PARENT_SCOPE)
  elseif(NOT all MATCHES "${regex}")
    set(failures "${failures}\n[${name}] output does not match '${regex}':\n${all}" PARENT_SCOPE)
  else()
    message(STATUS "[${name}] ok")
  endif()
endfunction()

# A 4x4x4 NRRD of float text values (no binary needed).
function(nrrd name values)
  file(WRITE ${OUT}/${name}.nrrd "NRRD0004\ntype: float\ndimension: 3\nsizes: 4 4 4\nspacings: 1 1 1\nencoding: ascii\n\n${values}\n")
endfunction()
set(nan "")
set(halfinf "")
set(big "")
set(ramp "")
foreach(i RANGE 63)
  string(APPEND nan "nan ")
  math(EXPR odd "${i} % 2")
  math(EXPR row "(${i} / 4) % 2")
  if(odd)
    string(APPEND halfinf "inf ")
  else()
    string(APPEND halfinf "1 ")
  endif()
  if(row)
    string(APPEND big "1e38 ")
  else()
    string(APPEND big "-1e38 ")
  endif()
  string(APPEND ramp "${i} ")
endforeach()
nrrd(allnan "${nan}")
nrrd(halfinf "${halfinf}")
nrrd(big "${big}")
nrrd(ramp "${ramp}")
expect(check_all_nan 3 "NaN voxels 64.*FAIL +64 non-finite voxels" check ${OUT}/allnan.nrrd)
expect(check_half_inf 3 "Inf voxels 32.*FAIL +32 non-finite voxels" check ${OUT}/halfinf.nrrd)
expect(check_1e38 3 "FAIL +32 gradients overflow" check ${OUT}/big.nrrd)
expect(check_ramp 0 "orientation LPS.*values +\\[0, 63\\].*PASS" check ${OUT}/ramp.nrrd)
expect(check_engine_orientation 0 "orientation RAS.*PASS" check ${DATA}/ct-engine/engine.nii.gz)

# MetaImage: 4x4x4 MET_SHORT needs 128 bytes; the raw file is text ('A' = 0x41).
string(REPEAT "A" 128 raw128)
string(REPEAT "A" 127 raw127)
function(mhd name extra raw)
  file(WRITE ${OUT}/${name}.raw "${raw}")
  file(WRITE ${OUT}/${name}.mhd "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n${extra}ElementDataFile = ${name}.raw\n")
endfunction()
mhd(short1 "ElementSpacing = 1 1 1\nDimSize = 4 4 4\nElementType = MET_SHORT\n" "${raw127}")
expect(mhd_one_byte_short 1 "short1.mhd: ElementDataFile 'short1.raw' holds 127 bytes.*needs 128 bytes \\(voxel data truncated\\)" check ${OUT}/short1.mhd)
mhd(uchar "ElementSpacing = 1 1 1\nDimSize = 4 4 4\nElementType = MET_UCHAR\n" "${raw128}")
expect(mhd_uchar_over_short 1 "uchar.mhd: ElementDataFile 'uchar.raw' holds 128 bytes; DimSize 4 x 4 x 4 of ElementType MET_UCHAR" check ${OUT}/uchar.mhd)
mhd(hsize "HeaderSize = 1000000\nElementSpacing = 1 1 1\nDimSize = 4 4 4\nElementType = MET_SHORT\n" "${raw128}")
expect(mhd_huge_header_size 1 "hsize.mhd: .*HeaderSize = 1000000" check ${OUT}/hsize.mhd)
mhd(nansp "ElementSpacing = nan 1 1\nDimSize = 4 4 4\nElementType = MET_SHORT\n" "${raw128}")
# One line, nothing of MetaIO's parse errors before it.
expect(mhd_nan_spacing 1 "^\n?[^\n]*nansp.mhd: field 'ElementSpacing' = nan 1 1: 'nan' is not a finite number\n$" check ${OUT}/nansp.mhd)
mhd(hugesp "ElementSpacing = 1e300 1 1\nDimSize = 4 4 4\nElementType = MET_SHORT\n" "${raw128}")
expect(mhd_huge_spacing 1 "hugesp.mhd: field 'ElementSpacing' along axis 0 is 1e\\+300 mm: the volume's extent" check ${OUT}/hugesp.mhd)
mhd(negdim "ElementSpacing = 1 1 1\nDimSize = -64 4 4\nElementType = MET_SHORT\n" "${raw128}")
expect(mhd_negative_dims 1 "negdim.mhd: field 'DimSize' = -64 4 4: axis 0 is -64" check ${OUT}/negdim.mhd)
# A header MetaIO cannot read (here a 2-D one with DimSize before NDims): MetaIO's own reason,
# once, not ITK's stale "No such file or directory".
file(WRITE ${OUT}/order.raw "${raw128}")
file(WRITE ${OUT}/order.mhd "ObjectType = Image\nDimSize = 8 8\nNDims = 2\nElementType = MET_SHORT\nElementDataFile = order.raw\n")
expect(mhd_2d_field_order 1 "^\n?[^\n]*order.mhd: MetaIO cannot read the header: DimSize defined prior to defining NDims\n$"
       check ${OUT}/order.mhd)
# A 2-D image is refused naming the field (it was read as one slice, 4 x 4 x 1, and touched).
file(WRITE ${OUT}/flat.raw "${raw128}")
file(WRITE ${OUT}/flat.mhd "ObjectType = Image\nNDims = 2\nDimSize = 8 8\nElementType = MET_SHORT\nElementDataFile = flat.raw\n")
expect(mhd_2d_image 1 "flat.mhd: NDims 2: a 2-D image, not a volume" check ${OUT}/flat.mhd)
file(WRITE ${OUT}/flat.nrrd "NRRD0004\ntype: float\ndimension: 2\nsizes: 2 2\nencoding: ascii\n\n1 2 3 4\n")
expect(nrrd_2d_image 1 "flat.nrrd: .*dimension 2: a 2-D image, not a volume" check ${OUT}/flat.nrrd)
file(WRITE ${OUT}/nodata.mhd "ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\nElementType = MET_SHORT\nElementDataFile = gone.raw\n")
expect(mhd_missing_data_file 1 "nodata.mhd: field 'ElementDataFile' = 'gone.raw': no such file" check ${OUT}/nodata.mhd)

# Scenes.
set(vol "\"volume\": {\"synthetic\": \"sphere\", \"dims\": [32, 32, 32], \"radius_vox\": 10}, \"isovalue\": 0")
# A label map whose values (the ramp, 0 to 63) no material but label 1 claims: the run stops
# before the engine with the file and the first unknown value.
file(WRITE ${OUT}/labels.json "{${vol}, \"materials\": {\"labels\": \"ramp.nrrd\", \"list\": [{\"name\": \"a\", \"label\": 1}]}}")
expect(scene_unknown_label 1 "ramp.nrrd: label value 2 \\(first at scan voxel \\([0-9, ]+\\)\\) is no material's: materials.list has labels 1"
       run ${OUT}/labels.json --out ${OUT}/o)
file(WRITE ${OUT}/dup.json "{${vol}, \"servo\": {\"stiffness_n_per_m\": 800, \"stiffness_n_per_m\": 80000}}")
expect(scene_duplicate_key 1 "dup.json: field 'servo.stiffness_n_per_m': appears twice" run ${OUT}/dup.json --out ${OUT}/o)
file(WRITE ${OUT}/overflow.json "{${vol}, \"servo\": {\"stiffness_n_per_m\": 1e999}}")
expect(scene_number_overflow 1 "overflow.json: not valid JSON.*1e999" run ${OUT}/overflow.json --out ${OUT}/o)
file(WRITE ${OUT}/far.json "{${vol}, \"script\": {\"ray_origin_frac\": [0.5, 0.5, -1e6]}}")
expect(scene_ray_origin_far 1 "far.json: field 'script.ray_origin_frac': each must be in \\[-2, 3\\]" run ${OUT}/far.json --out ${OUT}/o)
file(WRITE ${OUT}/light.json "{${vol}, \"device\": {\"mass_kg\": 1e-9}}")
expect(scene_device_too_light 1 "light.json: field 'device.mass_kg': must be at least .* kg" run ${OUT}/light.json --out ${OUT}/o)
# An empty name (out/ itself would be the output folder), a stroke without a direction, and a
# script too long to keep in memory: each named, before anything runs.
file(WRITE ${OUT}/noname.json "{${vol}, \"name\": \"\"}")
expect(scene_empty_name 1 "noname.json: field 'name': must not be empty" run ${OUT}/noname.json --out ${OUT}/o)
file(WRITE ${OUT}/nostroke.json "{${vol}, \"script\": {\"stroke_direction\": [0, 0, 0]}}")
expect(scene_zero_stroke 1 "nostroke.json: field 'script.stroke_direction': must not be \\[0, 0, 0\\]" run ${OUT}/nostroke.json --out ${OUT}/o)
file(WRITE ${OUT}/long.json "{${vol}, \"servo\": {\"rate_hz\": 100000}, \"script\": {\"hold_s\": 3600}}")
expect(scene_too_long 1 "long.json: field 'script': lasts about .* ticks, more than the .* the longest part is script.hold_s" run ${OUT}/long.json --out ${OUT}/o)
file(WRITE ${OUT}/slow.json "{${vol}, \"script\": {\"stroke_speed_m_s\": 1e-9}}")
expect(scene_too_slow 1 "slow.json: field 'script': .* the longest part is script.stroke_length_m / stroke_speed_m_s" run ${OUT}/slow.json --out ${OUT}/o)
file(WRITE ${OUT}/hugesp.json "{\"volume\": {\"path\": \"hugesp.mhd\"}, \"isovalue\": 1}")
expect(run_huge_spacing 1 "hugesp.mhd: field 'ElementSpacing'" run ${OUT}/hugesp.json --out ${OUT}/o)

# Command line.
expect(max_binding_negative 2 "--max-binding-mib: must be a number of MiB in \\(0, 1048576\\], got -1" check ${OUT}/ramp.nrrd --max-binding-mib -1)
expect(run_help_scene_format 0 "Scene file \\(JSON.*\"isovalue\".*Example:" run --help)
expect(device_after_subcommand 0 "PASS" check ${OUT}/ramp.nrrd --device 0)
# Range errors give readable bounds (no 300 digits of DBL_MAX).
expect(zoom_zero 2 "^--zoom: must be a finite number > 0, got 0\nRun with" render --zoom 0)
expect(distance_negative 2 "--distance: must be a finite number >= 0, got -1" render --distance -1)
# A NIfTI whose sform holds a NaN (found by fuzz_volume): ITK's matrix code aborted the
# process on it; now refused before ITK reads the header, naming the field and the value.
expect(check_nifti_nan_srow 1 "nan-srow.nii: NIfTI header field 'srow_z\\[1\\]' is -?nan: the orientation and voxel size must be finite"
       check ${CMAKE_CURRENT_LIST_DIR}/data/bad/nan-srow.nii)

# Each output's name must ask for the format its option writes; a file already there is kept.
set(head ${DATA}/ct-head-headsq/headsq_64x64x93_int16.mhd)
file(WRITE ${OUT}/keep.obj "kept\n")
expect(export_stl_named_obj 2 "--stl ${OUT}/keep.obj: the name must end in .stl \\(--obj writes .obj\\); nothing was written"
       export ${head} --iso 1150 --inside above --stl ${OUT}/keep.obj)
expect(export_vdb_named_nrrd 2 "--vdb ${OUT}/y.nrrd: the name must end in .vdb \\(--volume writes it\\)"
       export ${head} --vdb ${OUT}/y.nrrd)
expect(export_ply_named_xyz 2 "--ply ${OUT}/y.xyz: the name must end in .ply; nothing was written"
       export ${head} --iso 1150 --inside above --ply ${OUT}/y.xyz)
# A NaN isovalue is a usage error before anything is loaded or meshed (it used to mesh, then
# refuse with exit 2 naming the empty mesh).
expect(export_iso_nan 2 "--iso: must be a finite number \\(the isovalue in the volume's units.*\\), got nan"
       export ${head} --iso nan --inside above --stl ${OUT}/nan.stl)
# Mesh units are mm or m, nothing else (a usage error naming the value, nothing written).
expect(export_mesh_units_cm 2 "--mesh-units: must be mm or m, got cm"
       export ${head} --iso 1150 --inside above --stl ${OUT}/cm.stl --mesh-units cm)
expect(run_mesh_units_live 2 "--mesh-units is for drilled.stl, which a simulated run writes, not --live"
       run ${head} --live --mesh-units m)
file(READ ${OUT}/keep.obj kept)
if(NOT kept STREQUAL "kept\n" OR EXISTS ${OUT}/y.nrrd OR EXISTS ${OUT}/y.xyz OR EXISTS ${OUT}/nan.stl
   OR EXISTS ${OUT}/cm.stl)
  set(failures "${failures}\n[export names] an output was written or clobbered")
endif()

# A FIFO named as a volume (or a recording) is refused before open(), which would block until
# a writer came; nothing is written. (The old code blocked here until the timeout.)
execute_process(COMMAND mkfifo ${OUT}/f.mhd ${OUT}/f.vdb ${OUT}/f.rec)
file(WRITE ${OUT}/fifo.json "{\"volume\": {\"path\": \"f.mhd\"}, \"isovalue\": 1}")
set(fifo_says "f.mhd: not a regular file \\(a FIFO\\): a volume is read from a regular file or a DICOM series folder")
expect(fifo_check 1 "${fifo_says}" check ${OUT}/f.mhd)
expect(fifo_export 1 "${fifo_says}" export ${OUT}/f.mhd --vdb ${OUT}/fifo-out.vdb)
expect(fifo_export_vdb 1 "f.vdb: not a regular file \\(a FIFO\\): a .vdb volume is read from a regular file"
       export ${OUT}/f.vdb --vdb ${OUT}/fifo-out.vdb)
expect(fifo_run 1 "${fifo_says}" run ${OUT}/fifo.json --out ${OUT}/fifo-run)
expect(fifo_render 1 "${fifo_says}" render ${OUT}/fifo.json --out ${OUT}/fifo.png)
expect(fifo_replay 2 "f.rec: not a regular file \\(a FIFO\\): a recording is read from a regular file" replay ${OUT}/f.rec)
foreach(made fifo-out.vdb fifo.png)
  if(EXISTS ${OUT}/${made})
    set(failures "${failures}\n[fifo] ${made} was written")
  endif()
endforeach()
file(READ ${OUT}/fifo-run/summary.json fifo_summary)
if(NOT fifo_summary MATCHES "\"status\": \"failed\".*not a regular file \\(a FIFO\\)")
  set(failures "${failures}\n[fifo_run] summary.json does not say the run failed on the FIFO:\n${fifo_summary}")
endif()

if(failures)
  message(FATAL_ERROR "${failures}")
endif()
