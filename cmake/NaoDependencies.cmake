# Finds every dependency on the system. A missing one stops the configure step with the
# Debian package that provides it (toolchain/nao deps installs them all).
find_package(PkgConfig REQUIRED)
if(NAO_STATIC)
  # Static archives only (the robot build): CMake's platform files reset what a toolchain file
  # sets here, so it is set after them.
  set(CMAKE_FIND_LIBRARY_SUFFIXES .a)
endif()

macro(nao_require found what package)
  if(NOT ${found})
    message(FATAL_ERROR "${what} not found: install the Debian package '${package}' "
                        "(or run toolchain/nao deps, which installs everything this build needs)")
  endif()
endmacro()

find_package(Eigen3 3.4 QUIET NO_MODULE)
nao_require(Eigen3_FOUND "Eigen 3.4" libeigen3-dev)

# urdfdom's model types are header-only (liburdfdom-headers-dev, a dependency of liburdfdom-dev);
# its parser is a shared library, replaced by TinyXML (static archive) when NAO_URDF_READER=tinyxml.
find_path(NAO_URDF_HEADERS_INCLUDE_DIR urdf_model/model.h)
nao_require(NAO_URDF_HEADERS_INCLUDE_DIR "urdfdom's headers" liburdfdom-headers-dev)
find_path(NAO_TINYXML_INCLUDE_DIR tinyxml.h)
find_library(NAO_TINYXML_LIBRARY tinyxml)
nao_require(NAO_TINYXML_LIBRARY "TinyXML" libtinyxml-dev)
if(NAO_URDF_READER STREQUAL "urdfdom")
  pkg_check_modules(URDFDOM QUIET IMPORTED_TARGET urdfdom)
  nao_require(URDFDOM_FOUND "urdfdom" liburdfdom-dev)
endif()

pkg_check_modules(ODE QUIET IMPORTED_TARGET ode>=0.16)
nao_require(ODE_FOUND "ODE 0.16" libode-dev)

# ceres::TinySolver (header-only, triangulation): also nao_rt's reference library, which links
# no Ceres library.
find_path(NAO_TINY_SOLVER_INCLUDE_DIR ceres/tiny_solver.h)
nao_require(NAO_TINY_SOLVER_INCLUDE_DIR "Ceres Solver's headers (ceres/tiny_solver.h)" libceres-dev)
if(NOT NAO_RUNTIME_ONLY)
  find_package(Ceres 2.1 QUIET)
  nao_require(Ceres_FOUND "Ceres Solver 2.1" libceres-dev)
endif()

find_package(CLI11 QUIET CONFIG)
nao_require(CLI11_FOUND "CLI11" libcli11-dev)

find_package(nlohmann_json 3 QUIET CONFIG)
nao_require(nlohmann_json_FOUND "nlohmann-json" nlohmann-json3-dev)

if(NOT NAO_RUNTIME_ONLY)
  find_package(tomlplusplus 3 QUIET CONFIG)
  nao_require(tomlplusplus_FOUND "toml++" libtomlplusplus-dev)
endif()

# msgpack-c is header-only; used without Boost (MSGPACK_NO_BOOST), so its CMake package (which
# pulls Boost) is not needed: the header is enough.
find_path(NAO_MSGPACK_INCLUDE_DIR msgpack.hpp)
nao_require(NAO_MSGPACK_INCLUDE_DIR "msgpack-c" libmsgpack-cxx-dev)

if(NOT NAO_RUNTIME_ONLY)
  find_package(benchmark QUIET CONFIG)
  nao_require(benchmark_FOUND "Google Benchmark" libbenchmark-dev)
endif()

if(NAO_BUILD_TESTS)
  find_package(doctest QUIET CONFIG)
  nao_require(doctest_FOUND "doctest" doctest-dev)
  # KDL is an independent oracle for our kinematics: tests and benchmarks only.
  find_package(orocos_kdl QUIET CONFIG)
  nao_require(orocos_kdl_FOUND "Orocos KDL" liborocos-kdl-dev)
  # kdl_parser's own CMake config drags in ROS (urdf, pluginlib, ament) and its pkg-config
  # file names packages Debian does not ship: take the header and library directly.
  find_path(NAO_KDL_PARSER_INCLUDE kdl_parser/kdl_parser.hpp)
  find_library(NAO_KDL_PARSER_LIBRARY kdl_parser)
  if(NAO_KDL_PARSER_INCLUDE AND NAO_KDL_PARSER_LIBRARY)
    set(NAO_KDL_PARSER_FOUND TRUE)
    add_library(nao_kdl INTERFACE)
    target_include_directories(nao_kdl SYSTEM INTERFACE ${NAO_KDL_PARSER_INCLUDE} ${orocos_kdl_INCLUDE_DIRS})
    target_link_libraries(nao_kdl INTERFACE ${NAO_KDL_PARSER_LIBRARY} ${orocos_kdl_LIBRARIES})
  endif()
  nao_require(NAO_KDL_PARSER_FOUND "kdl_parser" libkdl-parser-dev)
endif()

if(NAO_WITH_TORCH)
  find_package(Torch QUIET CONFIG)
  if(NOT Torch_FOUND)
    message(FATAL_ERROR "libtorch not found. It is needed only to train policies (nao_toolchain train): "
                        "install the Debian package 'libtorch-dev', or configure with -DNAO_WITH_TORCH=OFF "
                        "to build everything else.")
  endif()
  # Gloo's headers: libtorch's c10d process group (data-parallel training, docs/training.md)
  # includes them; the library itself is already libtorch's dependency.
  find_package(Gloo QUIET CONFIG)
  nao_require(Gloo_FOUND "Gloo (c10d's collective backend)" libgloo-dev)
endif()
