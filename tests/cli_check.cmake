# Command-line checks of `firefly`: good runs (single frame and a sequence) and every bad
# input the tool promises to survive: one clear message, a non-zero exit, no output left,
# no input overwritten, no temporary left behind. Failures are collected (SEND_ERROR) so one
# run lists every broken promise.
cmake_minimum_required(VERSION 3.16)
file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}")
set(A "${DATA}/half_a.exr")
set(B "${DATA}/half_b.exr")

function(no_temporaries name)
  file(GLOB_RECURSE left LIST_DIRECTORIES false "${WORK}/*.tmp-*")
  if(left)
    message(SEND_ERROR "${name}: temporaries left behind: ${left}")
    file(REMOVE ${left})
  endif()
endfunction()

function(expect_ok name)
  execute_process(COMMAND ${FIREFLY} ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(SEND_ERROR "${name}: expected success, got ${rc}\n${out}\n${err}")
  else()
    message(STATUS "${name}: ok")
  endif()
  no_temporaries(${name})
endfunction()

# run_refused(name "message fragment" args...): a non-zero exit with one line naming the
# problem; sets `refused_rc` in the caller.
function(run_refused name fragment)
  execute_process(COMMAND ${FIREFLY} ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(refused_rc ${rc} PARENT_SCOPE)
  if(rc EQUAL 0)
    message(SEND_ERROR "${name}: expected failure, got success\n${out}")
    return()
  endif()
  if(NOT rc MATCHES "^[12]$")
    message(SEND_ERROR "${name}: exit code ${rc} (a crash or an abort?)\n${err}")
  endif()
  string(FIND "${err}" "${fragment}" pos)
  if(pos EQUAL -1)
    message(SEND_ERROR "${name}: message lacks '${fragment}':\n${err}")
  endif()
  string(REGEX MATCHALL "\n" lines "${err}")
  list(LENGTH lines nlines)
  if(nlines GREATER 1)
    message(SEND_ERROR "${name}: more than one line of complaint:\n${err}")
  endif()
  no_temporaries(${name})
  message(STATUS "${name}: refused as expected: ${err}")
endfunction()

# expect_fail(name "message fragment" output-that-must-not-exist args...)
function(expect_fail name fragment output)
  file(REMOVE "${output}")
  run_refused(${name} "${fragment}" ${ARGN})
  if(EXISTS "${output}")
    message(SEND_ERROR "${name}: left an output behind: ${output}")
  endif()
endfunction()

# expect_kept(name "message fragment" file-that-must-not-change args...)
function(expect_kept name fragment kept)
  file(SHA256 "${kept}" before)
  run_refused(${name} "${fragment}" ${ARGN})
  file(SHA256 "${kept}" after)
  if(NOT before STREQUAL after)
    message(SEND_ERROR "${name}: ${kept} was overwritten")
  endif()
endfunction()

# make(args...): runs the test-file helper.
function(make)
  execute_process(COMMAND ${MAKE_NAN} ${ARGN} RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "the test-file helper failed: ${ARGN}")
  endif()
endfunction()

# read_text(file var): the file's text, or "" (and an error) when it is missing.
function(read_text file var)
  set(${var} "" PARENT_SCOPE)
  if(NOT EXISTS "${file}")
    message(SEND_ERROR "${file} was not written")
    return()
  endif()
  file(READ "${file}" text)
  set(${var} "${text}" PARENT_SCOPE)
endfunction()

function(exr_info file var)
  execute_process(COMMAND ${MAKE_NAN} info ${file} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  string(STRIP "${out}" out)
  set(${var} "${out}" PARENT_SCOPE)
  if(NOT rc EQUAL 0)
    message(SEND_ERROR "cannot read ${file}: ${err}")
  endif()
endfunction()

# --- good runs ------------------------------------------------------------------------------
expect_ok(single ${A} ${B} -o ${WORK}/clean.exr --report ${WORK}/report.json --masks ${WORK}/mask --halves ${WORK}/half)
foreach(f clean.exr report.json mask_a.exr mask_b.exr half_a.exr half_b.exr)
  if(NOT EXISTS "${WORK}/${f}")
    message(SEND_ERROR "single: ${f} not written")
  endif()
endforeach()
file(READ "${WORK}/report.json" json)
string(JSON fireflies GET "${json}" frames 0 a fireflies)
string(JSON iters GET "${json}" options iterations)
if(fireflies LESS 1 OR NOT iters EQUAL 20)
  message(SEND_ERROR "report: fireflies ${fireflies}, iterations ${iters}")
endif()
expect_ok(help --help)
expect_ok(pfm ${DATA}/a_color.pfm ${DATA}/b_color.pfm --variance-a ${DATA}/a_variance.pfm
          --variance-b ${DATA}/b_variance.pfm -o ${WORK}/from_pfm.exr -q)
# an output named .pfm is PFM (colour, and the variance beside it), the OpenEXR output's bits,
# where before it was an OpenEXR file under a .pfm name
expect_ok(pfm_out ${DATA}/a_color.pfm ${DATA}/b_color.pfm --variance-a ${DATA}/a_variance.pfm
          --variance-b ${DATA}/b_variance.pfm -o ${WORK}/to_pfm.PFM -q --report ${WORK}/pfm_out.json)
execute_process(COMMAND ${MAKE_NAN} same_pfm ${WORK}/from_pfm.exr ${WORK}/to_pfm.PFM ${WORK}/to_pfm_variance.PFM
                RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(SEND_ERROR "pfm_out: the PFM output differs from the OpenEXR one: ${err}")
endif()
file(READ "${WORK}/pfm_out.json" json)
string(JSON pfm_var GET "${json}" frames 0 output_variance)
if(NOT pfm_var STREQUAL "${WORK}/to_pfm_variance.PFM")
  message(SEND_ERROR "pfm_out: the report names the variance output ${pfm_var}")
endif()
# a frame sequence: frames 7 and 8
foreach(f 0007 0008)
  configure_file(${A} ${WORK}/seq_a.${f}.exr COPYONLY)
  configure_file(${B} ${WORK}/seq_b.${f}.exr COPYONLY)
endforeach()
expect_ok(sequence "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr" --frames 7-8 -o "${WORK}/seq_clean.####.exr"
          --report ${WORK}/seq.json --threads 2)
foreach(f 0007 0008)
  if(NOT EXISTS "${WORK}/seq_clean.${f}.exr")
    message(SEND_ERROR "sequence: frame ${f} not written")
  endif()
endforeach()
file(READ "${WORK}/seq.json" json)
string(JSON second_lambdas GET "${json}" frames 1 lambdas_computed)
if(NOT second_lambdas EQUAL 0)
  message(SEND_ERROR "sequence: the second frame recomputed ${second_lambdas} lambdas (cache not reused)")
endif()

# --- bad input ------------------------------------------------------------------------------
set(O ${WORK}/bad.exr)
make(${WORK}/nan.pfm)  # 16x8, all NaN
make(${WORK}/nan2.pfm)
make(${WORK}/nan_var.pfm)  # the same, as a variance file of its own (one file is never two inputs)
make(${WORK}/nan2_var.pfm)
expect_fail(missing "cannot open" ${O} ${WORK}/nope.exr ${B} -o ${O})
file(WRITE ${WORK}/text.exr "this is not an image\n")
expect_fail(not_exr "not an OpenEXR file" ${O} ${WORK}/text.exr ${B} -o ${O})
# a truncated copy: the first 2000 bytes
execute_process(COMMAND head -c 2000 ${A} OUTPUT_FILE ${WORK}/truncated.exr)
expect_fail(truncated "truncated.exr" ${O} ${WORK}/truncated.exr ${B} -o ${O})
expect_fail(channels "missing channel" ${O} ${A} ${B} -o ${O} --channels X,Y,Z)
expect_fail(variance_channels "missing channel" ${O} ${A} ${B} -o ${O} --variance Var.R,Var.G,Var.B)
expect_fail(no_output "no output" ${O} ${A} ${B})
expect_fail(bad_option "unknown option" ${O} ${A} ${B} -o ${O} --frobnicate)
expect_fail(bad_kernel "kernel" ${O} ${A} ${B} -o ${O} --kernel 4)
expect_fail(bad_frames "frames" ${O} ${A} ${B} -o ${O} --frames 9-3)
expect_fail(missing_frame "frame 9" ${WORK}/seq_clean.0009.exr "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr"
            --frames 9-9 -o "${WORK}/seq_clean.####.exr")
# halves of different sizes: the 96x80 crop against a 16x8 image
expect_fail(sizes "differ in size" ${O} ${DATA}/a_color.pfm ${WORK}/nan.pfm --variance-a ${DATA}/a_variance.pfm
            --variance-b ${WORK}/nan_var.pfm -o ${O})
# NaN everywhere
expect_fail(all_nan "no valid pixel" ${O} ${WORK}/nan.pfm ${WORK}/nan2.pfm --variance-a ${WORK}/nan_var.pfm
            --variance-b ${WORK}/nan2_var.pfm -o ${O})

# --- 6: an output that is an input, under any name, is refused and nothing is written -------
configure_file(${A} ${WORK}/in_a.exr COPYONLY)
configure_file(${B} ${WORK}/in_b.exr COPYONLY)
set(IA ${WORK}/in_a.exr)
set(IB ${WORK}/in_b.exr)
expect_kept(output_is_input "is the input" ${IA} ${IA} ${IB} -o ${IA})
file(MAKE_DIRECTORY ${WORK}/sub)
expect_kept(output_is_input_spelled "is the input" ${IB} ${IA} ${IB} -o ${WORK}/sub/../in_b.exr)
file(CREATE_LINK ${IA} ${WORK}/hard.exr)
expect_kept(output_is_hard_link "is the input" ${IA} ${IA} ${IB} -o ${WORK}/hard.exr)
file(CREATE_LINK ${IA} ${WORK}/soft.exr SYMBOLIC)
expect_kept(output_is_symlink "is the input" ${IA} ${IA} ${IB} -o ${WORK}/soft.exr)
expect_kept(halves_are_inputs "is the input" ${IA} ${IA} ${IB} -o ${O} --halves ${WORK}/in)
expect_kept(masks_are_inputs "is the input" ${IB} ${IA} ${IB} -o ${O} --masks ${WORK}/in)
expect_kept(report_is_input "is the input" ${IA} ${IA} ${IB} -o ${O} --report ${IA})
configure_file(${A} ${WORK}/pv_before.png COPYONLY)  # an EXR under a preview's name
expect_kept(preview_is_input "is the input" ${WORK}/pv_before.png ${WORK}/pv_before.png ${IB} -o ${O} --preview ${WORK}/pv)
if(EXISTS ${O})
  message(SEND_ERROR "an output collision still wrote ${O}")
endif()
expect_fail(outputs_collide "same file" ${O} ${IA} ${IB} -o ${O} --halves ${WORK}/x --masks ${WORK}/x)
configure_file(${A} ${WORK}/seqin_a.0003.exr COPYONLY)
configure_file(${B} ${WORK}/seqin_b.0003.exr COPYONLY)
expect_kept(sequence_output_is_input "is the input" ${WORK}/seqin_a.0003.exr "${WORK}/seqin_a.####.exr"
            "${WORK}/seqin_b.####.exr" --frames 3-3 -o "${WORK}/seqin_a.####.exr")

# --- 13: the same file as both halves; alpha in one half only --------------------------------
expect_fail(same_halves "same file" ${O} ${IA} ${IA} -o ${O})
expect_fail(same_halves_link "same file" ${O} ${IA} ${WORK}/hard.exr -o ${O})
make(alpha ${A} ${WORK}/alpha_a.exr)
expect_fail(alpha_one_half "alpha channel A is in" ${O} ${WORK}/alpha_a.exr ${IB} -o ${O})
expect_ok(no_alpha ${WORK}/alpha_a.exr ${IB} -o ${O} --no-alpha -q)
make(alpha ${B} ${WORK}/alpha_b.exr)
expect_fail(alpha_to_pfm "holds no alpha" ${WORK}/alpha.pfm ${WORK}/alpha_a.exr ${WORK}/alpha_b.exr -o ${WORK}/alpha.pfm)
expect_ok(alpha_to_pfm_no_alpha ${WORK}/alpha_a.exr ${WORK}/alpha_b.exr -o ${WORK}/alpha.pfm --no-alpha -q)
foreach(f alpha.pfm alpha_variance.pfm)
  if(NOT EXISTS ${WORK}/${f})
    message(SEND_ERROR "alpha_to_pfm_no_alpha: ${f} not written")
  endif()
endforeach()
# a PFM output's variance file is an output too: never an input
file(CREATE_LINK ${IB} ${WORK}/vin_variance.pfm SYMBOLIC)
expect_kept(pfm_variance_is_input "is the input" ${IB} ${IA} ${IB} -o ${WORK}/vin.pfm)
file(REMOVE ${O})

# --- a frame is written whole or not at all: outputs the final rename cannot take ------------
# (a directory, a device or a pipe in the way; a name too long) are refused before anything is
# written, where before the masks and halves were renamed into place and the main output failed.
file(MAKE_DIRECTORY ${WORK}/out_dir.exr)
expect_fail(output_is_directory "not a regular file" ${WORK}/dirrun_a.exr ${IA} ${IB} -o ${WORK}/out_dir.exr
            --halves ${WORK}/dirrun --masks ${WORK}/dirmask)
foreach(f dirrun_b.exr dirmask_a.exr dirmask_b.exr)
  if(EXISTS ${WORK}/${f})
    message(SEND_ERROR "output_is_directory: ${f} was written")
  endif()
endforeach()
execute_process(COMMAND mkfifo ${WORK}/pipe.exr RESULT_VARIABLE fifo_rc)
if(fifo_rc EQUAL 0)
  run_refused(output_is_pipe "not a regular file" ${IA} ${IB} -o ${WORK}/pipe.exr)
  if(NOT IS_DIRECTORY ${WORK}/pipe.exr AND EXISTS ${WORK}/pipe.exr)
    execute_process(COMMAND test -p ${WORK}/pipe.exr RESULT_VARIABLE still_pipe)
    if(NOT still_pipe EQUAL 0)
      message(SEND_ERROR "output_is_pipe: the pipe was replaced by a file")
    endif()
  endif()
endif()
string(REPEAT "x" 252 long_name)
expect_fail(output_name_too_long "name too long" ${O} ${IA} ${IB} -o ${O} --masks ${WORK}/${long_name})
# a sequence's secondary outputs need '#' as its main output does (each frame overwrote the last)
expect_fail(sequence_halves_without_hash "needs '#' in --halves" ${WORK}/seq_clean.0007.exr
            "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr" --frames 7-8 -o "${WORK}/seq_clean.####.exr" --halves ${WORK}/h)
expect_fail(sequence_masks_without_hash "needs '#' in --masks" ${WORK}/seq_clean.0007.exr
            "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr" --frames 7-8 -o "${WORK}/seq_clean.####.exr" --masks ${WORK}/m)
# PFM variances: not ignored beside EXR halves, and never one file twice among the inputs
expect_fail(variance_with_exr_halves "go with PFM half buffers" ${O} ${IA} ${IB} -o ${O}
            --variance-a ${WORK}/nope.pfm --variance-b ${WORK}/nope2.pfm)
expect_fail(variance_twice "same file" ${O} ${DATA}/a_color.pfm ${DATA}/b_color.pfm -o ${O}
            --variance-a ${DATA}/a_variance.pfm --variance-b ${DATA}/a_variance.pfm)
expect_fail(colour_as_variance "same file" ${O} ${DATA}/a_color.pfm ${DATA}/b_color.pfm -o ${O}
            --variance-a ${DATA}/b_color.pfm --variance-b ${DATA}/a_color.pfm)

# --- 7: a planted temporary name is never followed -----------------------------------------
file(WRITE ${WORK}/victim.txt "victim\n")
foreach(planted ${WORK}/sym.exr.tmp ${WORK}/.sym.exr.tmp ${WORK}/report2.json.tmp)
  file(CREATE_LINK ${WORK}/victim.txt ${planted} SYMBOLIC)
endforeach()
expect_ok(planted_symlink ${IA} ${IB} -o ${WORK}/sym.exr --report ${WORK}/report2.json -q)
read_text(${WORK}/victim.txt victim)
if(NOT victim STREQUAL "victim\n" OR NOT EXISTS ${WORK}/sym.exr)
  message(SEND_ERROR "planted_symlink: the victim was written through a planted temporary link")
endif()

# --- 8: long paths and bytes >= 0x80 give a complete, valid JSON report ---------------------
set(long ${WORK})
foreach(i RANGE 4)
  string(REPEAT "d" 150 part)
  set(long "${long}/${part}${i}")
endforeach()
file(MAKE_DIRECTORY ${long})
expect_ok(long_path ${IA} ${IB} -o ${long}/clean.exr --report ${long}/report.json -q)
read_text(${long}/report.json json)
string(JSON got ERROR_VARIABLE jerr GET "${json}" frames 0 output)
string(LENGTH "${long}/clean.exr" want_len)
if(jerr OR NOT got STREQUAL "${long}/clean.exr" OR want_len LESS 600)
  message(SEND_ERROR "long_path: report unreadable or wrong (${want_len} characters): ${jerr}")
endif()
# a file name with the byte 0xff (not UTF-8), through the shell
execute_process(COMMAND sh -c "cp \"$1\" \"$2/raw_$(printf '\\377').exr\" && \"$3\" \"$2/raw_$(printf '\\377').exr\" \"$4\" -o \"$2/raw_out_$(printf '\\377').exr\" --report \"$2/raw.json\" -q"
                        sh ${IA} ${WORK} ${FIREFLY} ${IB} RESULT_VARIABLE rc ERROR_VARIABLE err)
read_text(${WORK}/raw.json json)
string(JSON got ERROR_VARIABLE jerr GET "${json}" frames 0 half_a)
if(NOT rc EQUAL 0 OR jerr)
  message(SEND_ERROR "raw_bytes: rc ${rc}, report not valid JSON: ${jerr}\n${err}")
endif()

# --- 9: hostile files: sizes are checked before anything is allocated ----------------------
file(WRITE ${WORK}/huge.pfm "PF\n65536 65536\n-1\n")  # 19 bytes claiming 48 GiB
expect_fail(pfm_huge_claim "truncated PFM" ${O} ${WORK}/huge.pfm ${DATA}/b_color.pfm
            --variance-a ${DATA}/a_variance.pfm --variance-b ${DATA}/b_variance.pfm -o ${O})
file(WRITE ${WORK}/big.pfm "PF\n16384 16384\n-1.0\n0123456789")  # 31 bytes claiming 3 GiB
expect_fail(pfm_big_claim "truncated PFM" ${O} ${WORK}/big.pfm ${DATA}/b_color.pfm
            --variance-a ${DATA}/a_variance.pfm --variance-b ${DATA}/b_variance.pfm -o ${O})
file(READ ${DATA}/a_color.pfm hex HEX)
string(REGEX REPLACE "^50460a39362038300a2d312e300a" "" data_hex "${hex}")  # "PF\n96 80\n-1.0\n"
string(LENGTH "${data_hex}" n)
if(NOT n EQUAL 184320)  # 96 x 80 x 3 floats
  message(FATAL_ERROR "unexpected header in a_color.pfm")
endif()
# hostile variants of a_color.pfm, written by the shell from hex (cmake writes text only)
function(pfm_variant name header_hex tail_hex)
  file(WRITE ${WORK}/${name}.hex "${header_hex}${data_hex}${tail_hex}")
  execute_process(COMMAND xxd -r -p ${WORK}/${name}.hex ${WORK}/${name}.pfm RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "cannot write ${name}.pfm (xxd missing?)")
  endif()
endfunction()
pfm_variant(crlf "50460d0a39362038300d0a2d312e300d0a" "")  # "PF\r\n96 80\r\n-1.0\r\n"
pfm_variant(comment "50460a23206120636f6d6d656e740a39362038300a2d312e300a" "")  # "# a comment" line
pfm_variant(trailing "50460a39362038300a2d312e300a" "00000000")  # 4 bytes too many
foreach(v crlf comment trailing)
  if(v STREQUAL "trailing")
    set(fragment "extra bytes")
  else()
    set(fragment "comment or CR")
  endif()
  expect_fail(pfm_${v} "${fragment}" ${O} ${WORK}/${v}.pfm ${DATA}/b_color.pfm
              --variance-a ${DATA}/a_variance.pfm --variance-b ${DATA}/b_variance.pfm -o ${O})
endforeach()
make(bigwindow ${A} ${WORK}/bigwindow.exr)
expect_fail(exr_big_window "too large for the file" ${O} ${WORK}/bigwindow.exr ${B} -o ${O})

# --- 10: FLT_MAX variance, duplicate channels, windows kept ---------------------------------
make(fill ${WORK}/half.pfm 16 8 3 0.5)
make(fill ${WORK}/half2.pfm 16 8 3 0.5)
make(fill ${WORK}/fltmax.pfm 16 8 3 max)
make(fill ${WORK}/fltmax2.pfm 16 8 3 max)
expect_ok(flt_max ${WORK}/half.pfm ${WORK}/half2.pfm --variance-a ${WORK}/fltmax.pfm --variance-b ${WORK}/fltmax2.pfm
          -o ${WORK}/fltmax.exr -q)
exr_info(${WORK}/fltmax.exr info)
if(NOT info MATCHES "nonfinite 0$")
  message(SEND_ERROR "flt_max: the combined variance overflowed: ${info}")
endif()
expect_fail(duplicate_colour "named twice" ${O} ${A} ${B} -o ${O} --channels R,R,R)
expect_fail(duplicate_alpha "named twice" ${O} ${A} ${B} -o ${O} --alpha-channel R)
expect_fail(duplicate_variance "named twice" ${O} ${A} ${B} -o ${O} --variance G)
foreach(origin "5;1000000000" "-20;-7")
  list(GET origin 0 x)
  list(GET origin 1 y)
  make(shift ${A} ${WORK}/win_a.exr ${x} ${y})
  make(shift ${B} ${WORK}/win_b.exr ${x} ${y})
  expect_ok(window_${x} ${WORK}/win_a.exr ${WORK}/win_b.exr -o ${WORK}/win.exr --masks ${WORK}/winmask -q)
  exr_info(${WORK}/win_a.exr want)
  foreach(f win.exr winmask_a.exr)
    exr_info(${WORK}/${f} got)
    string(REGEX REPLACE " nonfinite.*" "" got "${got}")
    string(REGEX REPLACE " nonfinite.*" "" want "${want}")
    if(NOT got STREQUAL want)
      message(SEND_ERROR "window_${x}: ${f} has '${got}', the input '${want}'")
    endif()
  endforeach()
endforeach()
# a PFM holds no window: a frame placed elsewhere is refused for a PFM output, not moved
expect_fail(pfm_window "no data or display window" ${WORK}/win.pfm ${WORK}/win_a.exr ${WORK}/win_b.exr
            -o ${WORK}/win.pfm)

# --- 11: a failing secondary output leaves no main output; the report says what happened ----
expect_fail(halves_fail "" ${O} ${A} ${B} -o ${O} --halves ${WORK}/nodir/h)
expect_fail(masks_fail "" ${O} ${A} ${B} -o ${O} --masks ${WORK}/nodir/m)
expect_fail(preview_fail "" ${O} ${A} ${B} -o ${O} --preview ${WORK}/nodir/p)
expect_fail(report_fail "" ${O} ${A} ${B} -o ${O} --report ${WORK}/nodir/r.json)
file(WRITE ${WORK}/seq_report.json "stale")
foreach(f 0007 0008)
  file(REMOVE ${WORK}/seq_clean.${f}.exr)
endforeach()
run_refused(sequence_bad_frame "frame 6" "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr" --frames 6-8
            -o "${WORK}/seq_clean.####.exr" --report ${WORK}/seq_report.json -q)
read_text(${WORK}/seq_report.json json)
string(JSON status ERROR_VARIABLE jerr GET "${json}" status)
string(JSON err6 ERROR_VARIABLE jerr6 GET "${json}" frames 0 error)
string(JSON n ERROR_VARIABLE jerrn LENGTH "${json}" frames)
if(jerr OR jerr6 OR jerrn OR NOT status STREQUAL "failed" OR NOT n EQUAL 3 OR NOT EXISTS ${WORK}/seq_clean.0008.exr)
  message(SEND_ERROR "sequence_bad_frame: the report does not say frame 6 failed and 7, 8 were written:\n${json}")
endif()
string(JSON err8 ERROR_VARIABLE jerr8 GET "${json}" frames 2 error)
if(NOT jerr8)
  message(SEND_ERROR "sequence_bad_frame: frame 8 reported an error: ${err8}")
endif()

# --- 12: numbers are checked for form and range --------------------------------------------
expect_fail(frames_overflow "frames" ${O} "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr"
            --frames 9223372036854775806-9223372036854775807 -o "${WORK}/seq_clean.####.exr")
expect_fail(frames_too_many "frames" ${O} "${WORK}/seq_a.####.exr" "${WORK}/seq_b.####.exr"
            --frames 0-999999999 -o "${WORK}/seq_clean.####.exr")
expect_fail(kernel_huge "kernel" ${O} ${A} ${B} -o ${O} --kernel 1e10)
expect_fail(kernel_big "kernel" ${O} ${A} ${B} -o ${O} --kernel 10000000001)
expect_fail(iterations_huge "iterations" ${O} ${A} ${B} -o ${O} --iterations 3e9)
expect_fail(iterations_big "iterations" ${O} ${A} ${B} -o ${O} --iterations 3000000000)
expect_fail(threads_fraction "threads" ${O} ${A} ${B} -o ${O} --threads 2.5)
expect_fail(threads_zero "threads" ${O} ${A} ${B} -o ${O} --threads 0)
expect_fail(significance_nan "significance" ${O} ${A} ${B} -o ${O} --significance nan)
expect_fail(sigma_inf "sigma" ${O} ${A} ${B} -o ${O} --sigma inf)
expect_fail(reduction_word "reduction" ${O} ${A} ${B} -o ${O} --reduction median)
no_temporaries(end)

# --- fuzz findings on the EXR path, kept as reproducers --------------------------------------
file(GLOB exr_regressions "${DATA}/../fuzz/regressions/exr/*")
foreach(f ${exr_regressions})
  get_filename_component(n ${f} NAME)
  expect_fail(exr_regression_${n} "" ${O} ${f} ${B} -o ${O})
endforeach()

# --- 18: --renders (N colour-only renders) and --buffers (K files with variance) ------------
# render_pfm(file seed [pixel hex]...): a 16x8 RGB PFM whose values are drawn, with the seed,
# from eight levels 0.3125 .. 0.75; each (pixel index, little-endian float in 8 hex digits)
# pair then sets that pixel's three channels. Written by xxd from hex, as the PFM variants.
function(render_pfm file seed)
  string(RANDOM LENGTH 384 ALPHABET ijklmnop RANDOM_SEED ${seed} hex)
  foreach(level i:0000a03e j:0000c03e k:0000e03e l:0000003f m:0000103f n:0000203f o:0000303f p:0000403f)
    string(REPLACE ":" ";" kv ${level})
    list(GET kv 0 letter)
    list(GET kv 1 value)
    string(REPLACE ${letter} ${value} hex "${hex}")
  endforeach()
  set(pairs ${ARGN})
  while(pairs)
    list(POP_FRONT pairs pixel value)
    math(EXPR at "${pixel} * 24")
    math(EXPR after "${at} + 24")
    string(SUBSTRING "${hex}" 0 ${at} before)
    string(SUBSTRING "${hex}" ${after} -1 rest)
    set(hex "${before}${value}${value}${value}${rest}")
  endwhile()
  file(WRITE ${file}.hex "50460a313620380a2d312e300a${hex}")  # "PF\n16 8\n-1.0\n"
  execute_process(COMMAND xxd -r -p ${file}.hex ${file} RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "cannot write ${file} (xxd missing?)")
  endif()
endfunction()

# same_bits(name file-a file-b): the two files hold the same bytes.
function(same_bits name a b)
  if(NOT EXISTS "${a}" OR NOT EXISTS "${b}")
    message(SEND_ERROR "${name}: ${a} or ${b} was not written")
    return()
  endif()
  file(SHA256 "${a}" ha)
  file(SHA256 "${b}" hb)
  if(NOT ha STREQUAL hb)
    message(SEND_ERROR "${name}: ${a} and ${b} differ")
  else()
    message(STATUS "${name}: same bits")
  endif()
endfunction()

# has_colour_and_variance(name file): the two-half mode reads R,G,B and Variance.R/G/B from
# the file and a copy, and refuses a file without them ("missing channel").
function(has_colour_and_variance name file)
  configure_file(${file} ${WORK}/channels_copy.exr COPYONLY)
  expect_ok(${name}_channels ${file} ${WORK}/channels_copy.exr -o ${WORK}/channels_check.exr -q)
endfunction()

# json_get(var file keys...): a value of a JSON report ("" and an error when it is missing).
function(json_get var file)
  read_text(${file} json)
  string(JSON got ERROR_VARIABLE jerr GET "${json}" ${ARGN})
  if(jerr)
    message(SEND_ERROR "${file}: no ${ARGN}: ${jerr}")
  endif()
  set(${var} "${got}" PARENT_SCOPE)
endfunction()

# Renders, each pixel drawn at random from 0.31 .. 0.75, except pixel P, 0.5 in every render
# but one, where a firefly (1000) sits; its twin set holds 0.5 there. The firefly's render is
# rebuilt at P from the others' mean, exactly 0.5: the output must hold the twin's bits.
set(half 0000003f)
set(firefly 00007a44)
foreach(case "4;0;72" "8;5;40")  # renders, the render with the firefly, its pixel
  list(GET case 0 n)
  list(GET case 1 hit)
  list(GET case 2 px)
  math(EXPR last "${n} - 1")
  set(with "")
  set(without "")
  foreach(i RANGE ${last})
    math(EXPR seed "${n} * 100 + ${i}")
    render_pfm(${WORK}/r${n}_${i}.pfm ${seed} ${px} ${half})
    list(APPEND with ${WORK}/r${n}_${i}.pfm)
    if(i EQUAL hit)
      render_pfm(${WORK}/t${n}_${i}.pfm ${seed} ${px} ${half})
      render_pfm(${WORK}/r${n}_${i}.pfm ${seed} ${px} ${firefly})
      list(APPEND without ${WORK}/t${n}_${i}.pfm)
    else()
      list(APPEND without ${WORK}/r${n}_${i}.pfm)
    endif()
  endforeach()
  set(renders${n} ${with})
  expect_ok(renders${n} --renders ${with} -o ${WORK}/r${n}.exr --report ${WORK}/r${n}.json --masks ${WORK}/r${n}m
            --halves ${WORK}/r${n}h)
  expect_ok(renders${n}_twin --renders ${without} -o ${WORK}/t${n}.exr --report ${WORK}/t${n}.json
            --masks ${WORK}/t${n}m -q)
  same_bits(renders${n}_firefly_gone ${WORK}/r${n}.exr ${WORK}/t${n}.exr)
  has_colour_and_variance(renders${n} ${WORK}/r${n}.exr)
  json_get(k ${WORK}/r${n}.json frames 0 buffers)
  json_get(mode ${WORK}/r${n}.json options mode)
  json_get(ff ${WORK}/r${n}.json frames 0 fireflies)
  json_get(ff_twin ${WORK}/t${n}.json frames 0 fireflies)
  json_get(hit_count ${WORK}/r${n}.json frames 0 per_buffer ${hit})
  json_get(hit_twin ${WORK}/t${n}.json frames 0 per_buffer ${hit})
  math(EXPR ff_want "${ff_twin} + 1")
  math(EXPR hit_want "${hit_twin} + 1")
  if(NOT k EQUAL n OR NOT mode STREQUAL "renders" OR NOT ff EQUAL ff_want OR NOT hit_count EQUAL hit_want)
    message(SEND_ERROR "renders${n}: report says ${k} buffers, mode ${mode}, fireflies ${ff} (twin ${ff_twin}), "
                       "render ${hit} ${hit_count} (twin ${hit_twin})")
  endif()
  foreach(i RANGE ${last})
    foreach(f r${n}m_${i}.exr r${n}h_${i}.exr)
      if(NOT EXISTS ${WORK}/${f})
        message(SEND_ERROR "renders${n}: ${f} not written")
      endif()
    endforeach()
  endforeach()
  file(SHA256 ${WORK}/r${n}m_${hit}.exr mask_with)
  file(SHA256 ${WORK}/t${n}m_${hit}.exr mask_without)
  if(mask_with STREQUAL mask_without)
    message(SEND_ERROR "renders${n}: the mask of render ${hit} does not mark the firefly")
  endif()
endforeach()
set(H4 ${WORK}/r4h_0.exr ${WORK}/r4h_1.exr ${WORK}/r4h_2.exr ${WORK}/r4h_3.exr)
# the cleaned renders, as EXR (--halves), are renders too: cleaning them again changes nothing
expect_ok(renders_exr --renders ${H4} -o ${WORK}/r4again.exr -q)
same_bits(renders_exr_same ${WORK}/r4again.exr ${WORK}/t4.exr)

# The variance of the mean of renders: constant renders 0.25, 0.5, 0.5, 0.75 have mean 0.5 and
# sample variance 1/24, so 1/96; two halves of 0.5 with variance 1/48 write the same bits.
set(fills "0.25;0.5;0.5;0.75")
set(constant "")
foreach(i RANGE 3)
  list(GET fills ${i} v)
  make(fill ${WORK}/c${i}.pfm 16 8 3 ${v})
  make(fill ${WORK}/c${i}_copy.pfm 16 8 3 ${v})
  list(APPEND constant ${WORK}/c${i}.pfm)
endforeach()
make(fill ${WORK}/var48.pfm 16 8 3 0.020833333333333332)
make(fill ${WORK}/var48_copy.pfm 16 8 3 0.020833333333333332)
expect_ok(renders_variance --renders ${constant} -o ${WORK}/rv.exr -q)
expect_ok(renders_variance_ref ${WORK}/c1.pfm ${WORK}/c2.pfm --variance-a ${WORK}/var48.pfm
          --variance-b ${WORK}/var48_copy.pfm -o ${WORK}/rv_ref.exr -q)
same_bits(renders_variance_is_spread_over_n ${WORK}/rv.exr ${WORK}/rv_ref.exr)

# --buffers with 2 files is the two-half mode, bit for bit (output, cleaned halves, masks).
expect_ok(buffers2 --buffers ${A} ${B} -o ${WORK}/kb2.exr --masks ${WORK}/kb2m --halves ${WORK}/kb2h -q)
same_bits(buffers2_output ${WORK}/kb2.exr ${WORK}/clean.exr)
same_bits(buffers2_half ${WORK}/kb2h_1.exr ${WORK}/half_b.exr)
same_bits(buffers2_mask ${WORK}/kb2m_0.exr ${WORK}/mask_a.exr)

# --buffers with 4 files: each made by the two-half mode from constant halves with variance 1
# (colour c, variance 0.5); their mean 0.5 has variance 4 x 0.5 / 16 = 0.125, as two halves
# of 0.5 with variance 0.25 each.
make(fill ${WORK}/var1.pfm 16 8 3 1)
make(fill ${WORK}/var1_copy.pfm 16 8 3 1)
make(fill ${WORK}/var4.pfm 16 8 3 0.25)
make(fill ${WORK}/var4_copy.pfm 16 8 3 0.25)
set(K4 "")
foreach(i RANGE 3)
  expect_ok(buffer_${i} ${WORK}/c${i}.pfm ${WORK}/c${i}_copy.pfm --variance-a ${WORK}/var1.pfm
            --variance-b ${WORK}/var1_copy.pfm -o ${WORK}/kb_${i}.exr -q)
  list(APPEND K4 ${WORK}/kb_${i}.exr)
endforeach()
expect_ok(buffers4 --buffers ${K4} -o ${WORK}/kb4.exr --report ${WORK}/kb4.json -q)
expect_ok(buffers4_ref ${WORK}/c1.pfm ${WORK}/c2.pfm --variance-a ${WORK}/var4.pfm --variance-b ${WORK}/var4_copy.pfm
          -o ${WORK}/kb4_ref.exr -q)
same_bits(buffers4_variance_is_sum_over_k2 ${WORK}/kb4.exr ${WORK}/kb4_ref.exr)
json_get(mode ${WORK}/kb4.json options mode)
json_get(n ${WORK}/kb4.json frames 0 per_buffer 3)
if(NOT mode STREQUAL "buffers")
  message(SEND_ERROR "buffers4: report mode ${mode}")
endif()
# real files with variance: the two halves and their cleaned versions; with the variances;
# 3 files (which always use them)
set(REAL4 ${A} ${B} ${WORK}/half_a.exr ${WORK}/half_b.exr)
expect_ok(buffers4_real --buffers ${REAL4} -o ${WORK}/kb4real.exr --masks ${WORK}/kb4m -q)
has_colour_and_variance(buffers4_real ${WORK}/kb4real.exr)
expect_ok(buffers4_use_variance --buffers ${REAL4} -o ${WORK}/kb4var.exr --use-variance --false-alarm 1e-3 --radius 2 -q)
expect_ok(buffers3 --buffers ${A} ${B} ${WORK}/half_a.exr -o ${WORK}/kb3.exr -q)

# A non-finite sample in one render is rebuilt (nothing non-finite is written); in more than
# half of the renders at a pixel it cannot be, and the frame is refused.
set(nan 0000c07f)
foreach(i RANGE 3)
  if(i EQUAL 0)
    render_pfm(${WORK}/nan1_${i}.pfm 900 10 ${nan})
  else()
    render_pfm(${WORK}/nan1_${i}.pfm 90${i})
  endif()
  if(i LESS 3)
    render_pfm(${WORK}/nan3_${i}.pfm 90${i} 10 ${nan})
  else()
    render_pfm(${WORK}/nan3_${i}.pfm 90${i})
  endif()
  list(APPEND NAN1 ${WORK}/nan1_${i}.pfm)
  list(APPEND NAN3 ${WORK}/nan3_${i}.pfm)
endforeach()
expect_ok(renders_nan_one --renders ${NAN1} -o ${WORK}/nan1.exr -q)
exr_info(${WORK}/nan1.exr info)
if(NOT info MATCHES "nonfinite 0$")
  message(SEND_ERROR "renders_nan_one: NaN written: ${info}")
endif()
set(O ${WORK}/bad.exr)
expect_fail(renders_nan_most "more than half of the renders" ${O} --renders ${NAN3} -o ${O})

# RGBA renders: alpha goes to the output (the two-half mode then finds A in it only)
set(RGBA "")
foreach(i RANGE 3)
  make(alpha ${WORK}/r4h_${i}.exr ${WORK}/rgba_${i}.exr)
  list(APPEND RGBA ${WORK}/rgba_${i}.exr)
endforeach()
expect_ok(renders_rgba --renders ${RGBA} -o ${WORK}/rgba.exr -q)
expect_fail(renders_rgba_has_alpha "alpha channel A is in ${WORK}/rgba.exr" ${O} ${WORK}/rgba.exr ${WORK}/r4.exr -o ${O})

# every refusal: one line, nothing written
list(SUBLIST renders4 0 3 three)
expect_ok(renders_three --renders ${three} -o ${WORK}/three.exr -q)
list(SUBLIST renders4 0 2 two)
expect_fail(renders_two "--renders needs at least 3 renders" ${O} --renders ${two} -o ${O})
expect_fail(buffers_one "--buffers needs at least 2 files" ${O} --buffers ${A} -o ${O})
set(many "")
foreach(i RANGE 64)
  list(APPEND many ${WORK}/r8_0.pfm)
endforeach()
expect_fail(renders_65 "at most 64" ${O} --renders ${many} -o ${O})
expect_fail(renders_sizes "differ in size" ${O} --renders ${three} ${DATA}/a_color.pfm -o ${O})
make(shift ${WORK}/r4h_3.exr ${WORK}/shifted_3.exr 5 5)
expect_fail(renders_windows "differ in data or display window" ${O} --renders ${WORK}/r4h_0.exr ${WORK}/r4h_1.exr
            ${WORK}/r4h_2.exr ${WORK}/shifted_3.exr -o ${O})
expect_fail(renders_channel "r4h_0.exr: missing channel(s) X, Y, Z" ${O} --renders ${H4} -o ${O} --channels X,Y,Z)
expect_fail(buffers_no_variance "r4h_0.exr: missing channel(s) Variance.R" ${O} --buffers ${H4} -o ${O})
expect_fail(renders_alpha_some "alpha channel A is in" ${O} --renders ${WORK}/rgba_0.exr ${WORK}/rgba_1.exr
            ${WORK}/rgba_2.exr ${WORK}/r4h_3.exr -o ${O})
expect_fail(renders_and_halves "cannot be mixed with positional inputs" ${O} ${A} --renders ${renders4} -o ${O})
expect_fail(renders_and_buffers "cannot be combined" ${O} --renders ${renders4} --buffers ${A} ${B} -o ${O})
expect_kept(renders_output_is_input "is the input" ${WORK}/r4_2.pfm --renders ${renders4} -o ${WORK}/r4_2.pfm)
expect_kept(renders_halves_are_inputs "is the input" ${WORK}/r4h_1.exr --renders ${H4} -o ${O} --halves ${WORK}/r4h)
expect_fail(renders_duplicate "render 1 and render 3 are the same file" ${O} --renders ${WORK}/r4_0.pfm
            ${WORK}/r4_1.pfm ${WORK}/r4_2.pfm ${WORK}/r4_1.pfm -o ${O})
file(CREATE_LINK ${WORK}/r4_1.pfm ${WORK}/r4_1_link.pfm SYMBOLIC)
expect_fail(renders_duplicate_link "same file" ${O} --renders ${WORK}/r4_0.pfm ${WORK}/r4_1.pfm ${WORK}/r4_2.pfm
            ${WORK}/r4_1_link.pfm -o ${O})
expect_fail(buffers_duplicate "buffer 0 and buffer 2 are the same file" ${O} --buffers ${A} ${B} ${A} -o ${O})
expect_fail(buffers_pfm "--buffers reads OpenEXR" ${O} --buffers ${DATA}/a_color.pfm ${DATA}/b_color.pfm -o ${O})
expect_fail(renders_use_variance "--use-variance needs --buffers" ${O} --renders ${renders4} -o ${O} --use-variance)
expect_fail(buffers2_use_variance "--use-variance needs --buffers" ${O} --buffers ${A} ${B} -o ${O} --use-variance)
expect_fail(renders_pair_option "--kernel is an option of the two-half detector" ${O} --renders ${renders4} -o ${O}
            --kernel 7)
expect_fail(halves_cross_option "--radius is an option of the K-buffer detector" ${O} ${A} ${B} -o ${O} --radius 2)
expect_fail(false_alarm_range "--false-alarm" ${O} --renders ${renders4} -o ${O} --false-alarm 0.5)
expect_fail(radius_range "--radius" ${O} --renders ${renders4} -o ${O} --radius 9)
expect_fail(energy_sigma_range "--energy-sigma" ${O} --renders ${renders4} -o ${O} --energy-sigma 0.5)
# the energy return's options reach the detector and the report, in both modes
function(check_energy_options name want)
  expect_ok(${name} ${ARGN} --report ${WORK}/${name}.json -q)
  file(READ "${WORK}/${name}.json" json)
  string(JSON ret GET "${json}" options return_energy)
  string(JSON sg GET "${json}" options energy_sigma)
  string(JSON coarse GET "${json}" options energy_coarse_sigma)
  string(JSON evidence GET "${json}" options energy_density_evidence)
  string(JSON returned GET "${json}" frames 0 energy_returned)
  if(NOT ret STREQUAL want OR (want STREQUAL "OFF" AND (NOT sg EQUAL 4 OR NOT returned EQUAL 0 OR NOT coarse EQUAL 16
                                                        OR NOT evidence EQUAL 3)))
    message(FATAL_ERROR "${name}: report has return_energy ${ret}, sigma ${sg} / ${coarse}, evidence ${evidence}, returned ${returned}")
  endif()
endfunction()
check_energy_options(renders_no_energy OFF --renders ${renders4} -o ${WORK}/noen.exr --no-energy-return --energy-sigma 4
                     --energy-coarse-sigma 16 --energy-density-evidence 3)
check_energy_options(halves_no_energy OFF ${A} ${B} -o ${WORK}/noen2.exr --no-energy-return --energy-sigma 4
                     --energy-coarse-sigma 16 --energy-density-evidence 3)
expect_fail(density_evidence_range "--energy-density-evidence" ${O} --renders ${renders4} -o ${O} --energy-density-evidence 0.5)
# a bucket written black in half A: found and rebuilt (the report's dropped, the masks' dropped
# channel), left as it was with --keep-black
make(black ${A} ${WORK}/black_a.exr 30 20 24)
function(check_dropped name want)
  expect_ok(${name} ${ARGN} --report ${WORK}/${name}.json -q)
  file(READ "${WORK}/${name}.json" json)
  string(JSON got GET "${json}" frames 0 a dropped)
  string(JSON other GET "${json}" frames 0 b dropped)
  if(NOT other EQUAL 0 OR (want STREQUAL "none" AND NOT got EQUAL 0) OR (want STREQUAL "square" AND got LESS 400))
    message(SEND_ERROR "${name}: ${got} + ${other} pixels found dropped (want ${want})")
  endif()
endfunction()
check_dropped(dropped_found square ${WORK}/black_a.exr ${B} -o ${WORK}/black.exr --masks ${WORK}/blackm)
check_dropped(dropped_kept none ${WORK}/black_a.exr ${B} -o ${WORK}/black_kept.exr --keep-black)
check_dropped(dropped_intact none ${A} ${B} -o ${WORK}/black_intact.exr)
# a bucket of 1e30 in half A's colour, its variance sane: found implausible and rebuilt from
# half B (the report's implausible); left with --keep-implausible
make(tile ${A} ${WORK}/garbage_a.exr 30 20 24 1e30)
function(check_implausible name want)
  expect_ok(${name} ${WORK}/garbage_a.exr ${B} -o ${WORK}/${name}.exr --report ${WORK}/${name}.json -q ${ARGN})
  json_get(got ${WORK}/${name}.json frames 0 a implausible)
  json_get(other ${WORK}/${name}.json frames 0 b implausible)
  if(NOT other EQUAL 0 OR (want STREQUAL "none" AND NOT got EQUAL 0) OR (want STREQUAL "square" AND NOT got EQUAL 576))
    message(SEND_ERROR "${name}: ${got} + ${other} pixels found implausible (want ${want})")
  endif()
endfunction()
check_implausible(implausible_found square)
check_implausible(implausible_kept none --keep-implausible)
# the same bucket black in two of four renders at once (renders: the halves' colours, A B A B;
# B's copies black): every one of its 2 x 576 pixel-renders found, none in the intact set
make(black ${B} ${WORK}/black_b.exr 30 20 24)
configure_file(${WORK}/black_b.exr ${WORK}/black_b2.exr COPYONLY)  # the tool refuses a file twice
configure_file(${A} ${WORK}/a2.exr COPYONLY)
configure_file(${B} ${WORK}/b2.exr COPYONLY)
function(check_dropped_renders name want)
  expect_ok(${name} --renders ${ARGN} -o ${WORK}/${name}.exr --report ${WORK}/${name}.json -q)
  json_get(got ${WORK}/${name}.json frames 0 dropped)
  if(NOT got EQUAL want)
    message(SEND_ERROR "${name}: ${got} pixel-renders found dropped (want ${want})")
  endif()
endfunction()
check_dropped_renders(dropped_two_renders 1152 ${A} ${WORK}/black_b.exr ${WORK}/a2.exr ${WORK}/black_b2.exr)
check_dropped_renders(dropped_two_renders_intact 0 ${A} ${B} ${WORK}/a2.exr ${WORK}/b2.exr)
# black in two of three renders: more than half unusable there, the frame refused, saying so
expect_fail(dropped_most_renders "dropped (black) bucket or implausible values in more than half of the renders" ${O}
            --renders ${A} ${WORK}/black_b.exr ${WORK}/black_b2.exr -o ${O})
expect_fail(energy_coarse_range "--energy-coarse-sigma" ${WORK}/noen3.exr ${A} ${B} -o ${WORK}/noen3.exr --energy-coarse-sigma 1)
check_energy_options(halves_energy_default ON ${A} ${B} -o ${WORK}/en2.exr)
expect_fail(renders_one_variance_name "--variance wants three names" ${O} --renders ${renders4} -o ${O} --variance V)

# a sequence of two frames: frame 1 has the firefly, frame 2 is the twin; both outputs hold
# the twin's bits. '#' is needed in every input path; a missing frame 3 is reported and the
# sequence goes on.
foreach(i RANGE 3)
  configure_file(${WORK}/r4_${i}.pfm ${WORK}/sr${i}.0001.pfm COPYONLY)
  if(i EQUAL 0)
    configure_file(${WORK}/t4_0.pfm ${WORK}/sr0.0002.pfm COPYONLY)
  else()
    configure_file(${WORK}/r4_${i}.pfm ${WORK}/sr${i}.0002.pfm COPYONLY)
  endif()
  list(APPEND SEQ "${WORK}/sr${i}.####.pfm")
endforeach()
expect_ok(renders_sequence --renders ${SEQ} --frames 1-2 -o "${WORK}/sr.####.exr" --report ${WORK}/sr.json -q)
same_bits(renders_sequence_1 ${WORK}/sr.0001.exr ${WORK}/t4.exr)
same_bits(renders_sequence_2 ${WORK}/sr.0002.exr ${WORK}/t4.exr)
# with threads: the frame's files read in parallel, the next frame read ahead, OpenEXR's pool;
# the same bits
expect_ok(renders_sequence_threads --renders ${SEQ} --frames 1-2 -o "${WORK}/srt.####.exr" --threads 3 -q)
same_bits(renders_sequence_threads_1 ${WORK}/srt.0001.exr ${WORK}/sr.0001.exr)
same_bits(renders_sequence_threads_2 ${WORK}/srt.0002.exr ${WORK}/sr.0002.exr)
json_get(ff1 ${WORK}/sr.json frames 0 fireflies)
json_get(ff2 ${WORK}/sr.json frames 1 fireflies)
math(EXPR ff_want "${ff2} + 1")
if(NOT ff1 EQUAL ff_want)
  message(SEND_ERROR "renders_sequence: fireflies ${ff1} and ${ff2}")
endif()
expect_fail(renders_sequence_hash "needs '#' in every input path" "${WORK}/sr.0001.exr" --renders ${WORK}/r4_0.pfm
            "${WORK}/sr1.####.pfm" "${WORK}/sr2.####.pfm" "${WORK}/sr3.####.pfm" --frames 1-2 -o "${WORK}/sr.####.exr")
file(REMOVE ${WORK}/sr.0001.exr ${WORK}/sr.0002.exr)
run_refused(renders_sequence_bad_frame "frame 3" --renders ${SEQ} --frames 1-3 -o "${WORK}/sr.####.exr"
            --report ${WORK}/sr_bad.json -q)
json_get(status ${WORK}/sr_bad.json status)
json_get(err3 ${WORK}/sr_bad.json frames 2 error)
if(NOT status STREQUAL "failed" OR NOT EXISTS ${WORK}/sr.0001.exr OR NOT EXISTS ${WORK}/sr.0002.exr)
  message(SEND_ERROR "renders_sequence_bad_frame: status ${status}, frames 1 and 2 not both written")
endif()
no_temporaries(renders_end)

# --- an input that is not a regular file is refused before it is opened ---------------------
# (opening a pipe waits for a writer that never comes); no output and no temporary are left,
# the report's included.
function(expect_pipe_refused name)
  file(REMOVE ${O})
  execute_process(COMMAND ${FIREFLY} ${ARGN} -o ${O} --report ${WORK}/pipe_report.json TIMEOUT 30
                  RESULT_VARIABLE rc ERROR_VARIABLE err)
  string(FIND "${err}" "in_pipe" named)
  string(FIND "${err}" "is not a regular file" pos)
  if(NOT rc EQUAL 1 OR named EQUAL -1 OR pos EQUAL -1 OR EXISTS ${O})
    message(SEND_ERROR "${name}: a pipe as input: exit ${rc}\n${err}")
  else()
    message(STATUS "${name}: refused as expected: ${err}")
  endif()
  no_temporaries(${name})
endfunction()
execute_process(COMMAND mkfifo ${WORK}/in_pipe.exr ${WORK}/in_pipe.pfm RESULT_VARIABLE fifo_rc)
if(fifo_rc EQUAL 0)
  expect_pipe_refused(pipe_exr_half ${WORK}/in_pipe.exr ${B})
  expect_pipe_refused(pipe_pfm_half ${WORK}/in_pipe.pfm ${DATA}/b_color.pfm --variance-a ${DATA}/a_variance.pfm
                      --variance-b ${DATA}/b_variance.pfm)
  expect_pipe_refused(pipe_pfm_variance ${DATA}/a_color.pfm ${DATA}/b_color.pfm --variance-a ${DATA}/a_variance.pfm
                      --variance-b ${WORK}/in_pipe.pfm)
  expect_pipe_refused(pipe_render --renders ${WORK}/r4_0.pfm ${WORK}/r4_1.pfm ${WORK}/in_pipe.pfm)
  expect_pipe_refused(pipe_buffer --buffers ${A} ${B} ${WORK}/in_pipe.exr)
endif()

# --- outputs of different frames that are one file are refused ------------------------------
# frame 10's half xf_h10_a.exr is frame 0's mask xf_h1 + 0 + _a.exr
foreach(f 00 10)
  configure_file(${A} ${WORK}/xf_a${f}.exr COPYONLY)
  configure_file(${B} ${WORK}/xf_b${f}.exr COPYONLY)
endforeach()
set(both "xf_h10_a.exr (--masks, frame 0) and ${WORK}/xf_h10_a.exr (--halves, frame 10) are the same file")
expect_fail(outputs_collide_across_frames "${both}" ${WORK}/xf_o0.exr "${WORK}/xf_a##.exr" "${WORK}/xf_b##.exr"
            --frames 0-10:10 -o "${WORK}/xf_o#.exr" --halves "${WORK}/xf_h#" --masks "${WORK}/xf_h1#")
if(EXISTS ${WORK}/xf_h10_a.exr OR EXISTS ${WORK}/xf_o10.exr)
  message(SEND_ERROR "outputs_collide_across_frames: outputs were written")
endif()
expect_fail(report_is_sequence_output "same file" ${WORK}/xf_o0.exr "${WORK}/xf_a##.exr" "${WORK}/xf_b##.exr"
            --frames 0-10:10 -o "${WORK}/xf_o#.exr" --report ${WORK}/xf_o10.exr)

# --- PFM and OpenEXR inputs mixed: a PFM lies at the origin ---------------------------------
set(MIXED ${WORK}/r4_0.pfm ${WORK}/r4h_1.exr ${WORK}/r4h_2.exr ${WORK}/r4h_3.exr)
expect_ok(renders_mixed --renders ${MIXED} -o ${WORK}/mixed.exr -q)
expect_ok(renders_mixed_exr_first --renders ${WORK}/r4h_1.exr ${WORK}/r4_0.pfm ${WORK}/r4h_2.exr ${WORK}/r4h_3.exr
          -o ${WORK}/mixed2.exr -q)
foreach(f mixed.exr mixed2.exr)
  exr_info(${WORK}/${f} info)
  if(NOT info STREQUAL "data 0 0 15 7 display 0 0 15 7 nonfinite 0")
    message(SEND_ERROR "renders_mixed: ${f} has '${info}'")
  endif()
endforeach()
expect_fail(renders_mixed_shifted "differ in data or display window" ${O} --renders ${WORK}/r4_0.pfm ${WORK}/r4h_1.exr
            ${WORK}/r4h_2.exr ${WORK}/shifted_3.exr -o ${O})
# two halves, one PFM (its variance from --variance-a) and one OpenEXR (its own variance)
expect_ok(halves_mixed ${DATA}/a_color.pfm ${B} --variance-a ${DATA}/a_variance.pfm -o ${WORK}/hmixed.exr -q)
exr_info(${WORK}/hmixed.exr info)
if(NOT info STREQUAL "data 0 0 95 79 display 0 0 95 79 nonfinite 0")
  message(SEND_ERROR "halves_mixed: hmixed.exr has '${info}'")
endif()
expect_fail(halves_mixed_exr_variance "--variance-b goes with a PFM half" ${O} ${DATA}/a_color.pfm ${B}
            --variance-a ${DATA}/a_variance.pfm --variance-b ${DATA}/b_variance.pfm -o ${O})
expect_fail(halves_mixed_no_variance "give --variance-a" ${O} ${DATA}/a_color.pfm ${B} -o ${O})

# --- an option given an empty value is refused, never taken for "not given" ----------------
# (execute_process is called directly: an empty argument does not survive a function's ARGN)
function(expect_empty_refused name rc err)
  string(FIND "${err}" "empty" pos)
  if(NOT rc EQUAL 2 OR pos EQUAL -1 OR EXISTS ${O})
    message(SEND_ERROR "${name}: an empty value: exit ${rc}\n${err}")
  else()
    message(STATUS "${name}: refused as expected: ${err}")
  endif()
  no_temporaries(${name})
endfunction()
foreach(opt --frames --channels --variance --alpha-channel --report --halves --masks --preview --variance-a
            --variance-b)
  file(REMOVE ${O})
  execute_process(COMMAND ${FIREFLY} ${A} ${B} -o ${O} ${opt} "" RESULT_VARIABLE rc ERROR_VARIABLE err)
  expect_empty_refused(empty${opt} "${rc}" "${err}")
endforeach()
file(REMOVE ${O})
execute_process(COMMAND ${FIREFLY} ${A} ${B} -o "" RESULT_VARIABLE rc ERROR_VARIABLE err)
expect_empty_refused(empty_output "${rc}" "${err}")
execute_process(COMMAND ${FIREFLY} "" ${B} -o ${O} RESULT_VARIABLE rc ERROR_VARIABLE err)
expect_empty_refused(empty_half "${rc}" "${err}")
execute_process(COMMAND ${FIREFLY} --renders ${WORK}/r4_0.pfm "" ${WORK}/r4_2.pfm ${WORK}/r4_3.pfm -o ${O}
                RESULT_VARIABLE rc ERROR_VARIABLE err)
expect_empty_refused(empty_render "${rc}" "${err}")

# --- a replaced output keeps its permission bits --------------------------------------------
file(REMOVE ${WORK}/private.exr)
file(TOUCH ${WORK}/private.exr)
file(CHMOD ${WORK}/private.exr PERMISSIONS OWNER_READ OWNER_WRITE)
expect_ok(private_output ${A} ${B} -o ${WORK}/private.exr -q)
execute_process(COMMAND stat -c %a ${WORK}/private.exr OUTPUT_VARIABLE mode OUTPUT_STRIP_TRAILING_WHITESPACE)
if(NOT mode STREQUAL "600")
  message(SEND_ERROR "private_output: a 600 output became ${mode}")
endif()

# --- numbers that underflow (a denormal, or 0) are taken; those that overflow are refused ---
expect_ok(tolerance_denormal ${A} ${B} -o ${WORK}/tiny.exr --tolerance 1e-320 -q)
expect_ok(tolerance_underflow ${A} ${B} -o ${WORK}/tiny.exr --tolerance 1e-400 -q)
expect_ok(relative_error_denormal ${A} ${B} -o ${WORK}/tiny.exr --max-relative-error 4.9e-324 -q)
expect_fail(tolerance_overflow "--tolerance" ${O} ${A} ${B} -o ${O} --tolerance 1e400)

# --- the progress line is printed only once a frame's outputs are committed -----------------
# A folder whose path leaves room for a temporary's name (at most 212 bytes) but not for a
# 255-byte final name within PATH_MAX (4096 with its NUL): the write succeeds, the rename fails.
string(LENGTH "${WORK}" n)
math(EXPR pad "3860 - ${n} - 1")
set(deep ${WORK})
while(pad GREATER 0)
  if(pad GREATER 201)
    set(part_len 150)
  else()
    set(part_len ${pad})
  endif()
  string(REPEAT "p" ${part_len} part)
  set(deep "${deep}/${part}")
  math(EXPR pad "${pad} - ${part_len} - 1")
endwhile()
file(MAKE_DIRECTORY ${deep})
string(REPEAT "o" 251 leaf)
string(REPEAT "s" 247 seq_leaf)
foreach(case "single;${deep}/${leaf}.exr;${A};${B}"
             "sequence;${deep}/${seq_leaf}####.exr;${WORK}/seq_a.####.exr;${WORK}/seq_b.####.exr;--frames;7-7")
  list(POP_FRONT case what)
  execute_process(COMMAND ${FIREFLY} -o ${case} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  string(FIND "${out}" ": 96x80," printed)
  if(NOT rc EQUAL 1 OR NOT printed EQUAL -1)
    message(SEND_ERROR "progress_after_commit_${what}: exit ${rc}, a progress line for a frame not written:\n${out}")
  else()
    message(STATUS "progress_after_commit_${what}: ok")
  endif()
  no_temporaries(progress_after_commit_${what})
endforeach()
execute_process(COMMAND ${FIREFLY} ${A} ${B} -o ${WORK}/progress.exr RESULT_VARIABLE rc OUTPUT_VARIABLE out)
string(FIND "${out}" "progress.exr: 96x80," printed)
if(NOT rc EQUAL 0 OR printed EQUAL -1)
  message(SEND_ERROR "progress_printed: exit ${rc}, no progress line for a frame written:\n${out}")
endif()
