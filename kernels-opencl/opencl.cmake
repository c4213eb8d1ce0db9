# opencl.cmake — the OpenCL backend (kernels-opencl/), included by the top-level CMakeLists.txt
# after the library and the tests are defined. It finds OpenCL (ICD loader + headers), embeds
# every kernels-opencl/*.cl file into a generated C file at build time (cmake/EmbedCL.cmake;
# editing a .cl file re-runs it), adds the backend's C files to lumosaic_core (linked into every
# program, where the backend registers itself), and sets the environment of the OpenCL tests.
find_package(OpenCL REQUIRED)
file(GLOB LM_CL_KERNELS CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/kernels-opencl/*.cl)
list(SORT LM_CL_KERNELS)
# common.cl (shared helpers) comes first: the files are compiled as one program.
list(REMOVE_ITEM LM_CL_KERNELS ${CMAKE_SOURCE_DIR}/kernels-opencl/common.cl)
list(PREPEND LM_CL_KERNELS ${CMAKE_SOURCE_DIR}/kernels-opencl/common.cl)
file(GLOB LM_CL_C_SOURCES CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/kernels-opencl/*.c)
set(LM_CL_EMBEDDED ${CMAKE_BINARY_DIR}/generated/cl_sources.c)
string(REPLACE ";" "|" LM_CL_KERNELS_ARG "${LM_CL_KERNELS}")
add_custom_command(OUTPUT ${LM_CL_EMBEDDED}
  COMMAND ${CMAKE_COMMAND} -DOUT=${LM_CL_EMBEDDED} -DSOURCES=${LM_CL_KERNELS_ARG}
          -P ${CMAKE_SOURCE_DIR}/cmake/EmbedCL.cmake
  DEPENDS ${LM_CL_KERNELS} ${CMAKE_SOURCE_DIR}/cmake/EmbedCL.cmake
  COMMENT "Embedding OpenCL kernels (kernels-opencl/*.cl)"
  VERBATIM)
target_sources(lumosaic_core PRIVATE ${LM_CL_C_SOURCES} ${LM_CL_EMBEDDED})
target_link_libraries(lumosaic_core PUBLIC OpenCL::OpenCL)
# The backend registers itself as "opencl" from a constructor in cl_backend.c; nothing above
# tensor/ refers to it, so every program linking the (static) library is told to link that file.
target_link_options(lumosaic_core INTERFACE "LINKER:--undefined=lm_cl_backend_create")
target_compile_definitions(lumosaic_core PUBLIC CL_TARGET_OPENCL_VERSION=120 LM_HAVE_OPENCL=1)

# The OpenCL tests. Under sanitizers, the driver (PoCL, not built with ASan) leaks what its
# LLVM JIT allocates while compiling kernels on a cold kernel cache: LeakSanitizer suppresses
# allocations made inside the driver's libraries only (kernels-opencl/lsan-opencl.supp), so a
# leak in our code still fails the test.
file(GLOB LM_CL_TESTS CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/tests/test_opencl_*.c)
foreach(src ${LM_CL_TESTS})
  get_filename_component(name ${src} NAME_WE)
  if(NOT TEST ${name}) # (the library-only build defines no tests)
    continue()
  endif()
  set_property(TEST ${name} APPEND PROPERTY LABELS "opencl")
  if(LM_SANITIZE)
    set_property(TEST ${name} APPEND PROPERTY ENVIRONMENT
      "LSAN_OPTIONS=suppressions=${CMAKE_SOURCE_DIR}/kernels-opencl/lsan-opencl.supp")
  endif()
endforeach()
