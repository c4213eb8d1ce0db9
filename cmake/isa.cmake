# isa.cmake — the hot CPU kernels compiled once per instruction set (tensor/isa.h).
# Each file of LM_ISA_KERNELS is compiled into one object library per level: generic (the
# build's baseline flags), and on x86-64 also avx2 (-march=x86-64-v3) and avx512
# (-march=x86-64-v4). Every exported kernel symbol S of a variant is renamed S_<level> on the
# command line (LM_ISA_SYMBOLS), so the sources stay plain C; tensor/ops/isa_dispatch.c
# defines S itself and calls the variant of the level chosen at run time.
set(LM_ISA_KERNELS
  ${CMAKE_SOURCE_DIR}/tensor/ops/conv2d_winograd.c
  ${CMAKE_SOURCE_DIR}/tensor/ops/sgemm_panel.c
  ${CMAKE_SOURCE_DIR}/tensor/ops/conv2d_direct.c
  ${CMAKE_SOURCE_DIR}/tensor/ops/conv2d_depthwise.c
  ${CMAKE_SOURCE_DIR}/tensor/ops/gelu_fast.c
  ${CMAKE_SOURCE_DIR}/models/lmmse_direct.c)
set(LM_ISA_SYMBOLS
  lm_conv2d_winograd_applies lm_conv2d_winograd_fwd lm_conv2d_winograd_bwd_x
  lm_conv2d_winograd_bwd_w lm_panel_pack lm_sgemm_panel lm_conv2d_direct_applies
  lm_conv2d_direct_fwd lm_conv2d_dw_fwd lm_conv2d_dw_bwd_x lm_conv2d_dw_bwd_w
  lm_lmmse_direct_rows lm_gelu_fwd_fast lm_gelu_bwd_fast)

if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
  set(LM_ISA_X86 ON)
  set(LM_ISA_LEVELS generic avx2 avx512)
else()
  set(LM_ISA_X86 OFF)
  set(LM_ISA_LEVELS generic)
endif()
# (8-wide GCC vectors passed between static inline helpers: no ABI is involved)
set(LM_ISA_FLAGS_generic -Wno-psabi)
set(LM_ISA_FLAGS_avx2 -march=x86-64-v3)
set(LM_ISA_FLAGS_avx512 -march=x86-64-v4)

# lm_isa_variants(TARGET): add the variant objects to TARGET (the core library).
function(lm_isa_variants target)
  foreach(level ${LM_ISA_LEVELS})
    set(obj lm_isa_${level})
    add_library(${obj} OBJECT ${LM_ISA_KERNELS})
    set_target_properties(${obj} PROPERTIES POSITION_INDEPENDENT_CODE ON) # (the shared library)
    target_include_directories(${obj} PRIVATE ${CMAKE_SOURCE_DIR})
    target_link_libraries(${obj} PRIVATE OpenMP::OpenMP_C)
    set(defs "")
    foreach(sym ${LM_ISA_SYMBOLS})
      list(APPEND defs "${sym}=${sym}_${level}")
    endforeach()
    target_compile_definitions(${obj} PRIVATE ${defs} LM_ISA_LEVEL_NAME="${level}")
    if(LM_MARCH) # one target for the whole build: every level compiled for it
      target_compile_options(${obj} PRIVATE -Wno-psabi)
    elseif(LM_ISA_FLAGS_${level})
      target_compile_options(${obj} PRIVATE ${LM_ISA_FLAGS_${level}})
    endif()
    target_sources(${target} PRIVATE $<TARGET_OBJECTS:${obj}>)
  endforeach()
  if(LM_ISA_X86)
    target_compile_definitions(${target} PRIVATE LM_ISA_X86_VARIANTS=1)
  endif()
endfunction()
