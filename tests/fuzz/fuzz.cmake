# fuzz.cmake — the fuzz harnesses of tests/fuzz (README.md there), included by CMakeLists.txt.
# Every harness is built twice: fuzz_<name>_replay (replay_main.c feeds it the files of
# tests/fuzz/corpus/<name> and tests/fuzz/regress/<name>; a CTest test, label "fuzz", in every
# build) and, with -DLM_FUZZ=ON under clang, fuzz_<name> linked with libFuzzer
# (target `fuzz` builds them all).
set(LM_FUZZ_HARNESSES frame exr_cube mat cave safetensors checkpoint system run_config
    study_config sidecar doe)
if(LM_FUZZ)
  add_custom_target(fuzz)
  # fuzz_mat's reader child (data/isolate.h): the small helper beside it, not the harness again
  add_dependencies(fuzz lumosaic-reader)
endif()
foreach(h ${LM_FUZZ_HARNESSES})
  set(src ${CMAKE_SOURCE_DIR}/tests/fuzz/fuzz_${h}.c)
  add_executable(fuzz_${h}_replay ${src} ${CMAKE_SOURCE_DIR}/tests/fuzz/replay_main.c)
  set(lib lumosaic_core)
  if(h STREQUAL "study_config")
    set(lib lumosaic_study) # (which links lumosaic_core)
  endif()
  target_link_libraries(fuzz_${h}_replay PRIVATE ${lib})
  set(dirs)
  foreach(kind corpus regress)
    if(IS_DIRECTORY ${CMAKE_SOURCE_DIR}/tests/fuzz/${kind}/${h})
      list(APPEND dirs ${CMAKE_SOURCE_DIR}/tests/fuzz/${kind}/${h})
    endif()
  endforeach()
  add_test(NAME fuzz_replay_${h} COMMAND fuzz_${h}_replay ${dirs})
  set_tests_properties(fuzz_replay_${h} PROPERTIES LABELS "fuzz" ENVIRONMENT "${LM_TEST_ENV}")
  if(LM_FUZZ)
    add_executable(fuzz_${h} ${src})
    target_link_libraries(fuzz_${h} PRIVATE ${lib})
    target_link_options(fuzz_${h} PRIVATE -fsanitize=fuzzer)
    add_dependencies(fuzz fuzz_${h})
  endif()
endforeach()
