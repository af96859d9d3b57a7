# Third-party dependencies, all from Debian 12 packages (scripts/setup.sh installs them).
#
# Targets made available here:
#   Eigen3::Eigen          linear algebra (engine)
#   drillbif::sundials     CVODES + serial N_Vector + dense SUNMatrix/SUNLinearSolver (engine)
#   protobuf::libprotobuf  protobuf::protoc                                  (proto/)
#   CLI11::CLI11           command line parsing                              (client/)
#   GTest::gtest_main GTest::gmock                                           (tests/)
#   benchmark::benchmark                                                     (bench/)
#   drillbif::grpc         gRPC C++ (grpc++), DRILLBIF_GRPC_CPP_PLUGIN       (service, later)
#   spdlog::spdlog         logging                                           (service, later)
#   SQLite::SQLite3        store                                             (service, later)
#   OpenSSL::Crypto        SHA-256 of the service's cache keys               (server/)
#   drillbif::grpc_reflection  gRPC server reflection (grpc++_reflection)    (server/)
#   drillbif::microhttpd   GNU libmicrohttpd: the REST gateway's HTTP server  (server/)
#   utf8cpp                UTF-8 validation of what the gateway passes on    (server/)
#   prometheus-cpp::core   Prometheus registry and text exposition           (server/)
#   drillbif::httplib      cpp-httplib: the HTTP client of the REST tests and of
#                          bench/http_bench                                  (tests/, bench/)
# The engine links only Eigen and SUNDIALS (see /work/shared/ARCHITECTURE.md).

# --- Eigen -------------------------------------------------------------------------------------
find_package(Eigen3 3.3 REQUIRED CONFIG)

# --- SUNDIALS ----------------------------------------------------------------------------------
# Debian's libsundials-dev ships SUNDIALSConfig.cmake (6.4.1); use it when it loads, otherwise
# fall back to plain find_library. The engine uses the SUNDIALS >= 6 API (SUNContext).
find_package(SUNDIALS 6 CONFIG QUIET)
add_library(drillbif::sundials INTERFACE IMPORTED GLOBAL)
if(SUNDIALS_FOUND AND TARGET SUNDIALS::cvodes AND TARGET SUNDIALS::nvecserial
   AND TARGET SUNDIALS::sunmatrixdense AND TARGET SUNDIALS::sunlinsoldense)
  target_link_libraries(drillbif::sundials INTERFACE SUNDIALS::cvodes SUNDIALS::nvecserial
                        SUNDIALS::sunmatrixdense SUNDIALS::sunlinsoldense)
  set(DRILLBIF_SUNDIALS_HOW "CMake config (${SUNDIALS_DIR})")
else()
  find_path(DRILLBIF_SUNDIALS_INCLUDE_DIR NAMES cvodes/cvodes.h REQUIRED)
  set(_drillbif_sundials_libs)
  foreach(_lib sundials_cvodes sundials_nvecserial sundials_sunmatrixdense sundials_sunlinsoldense)
    find_library(DRILLBIF_${_lib}_LIBRARY NAMES ${_lib} REQUIRED)
    list(APPEND _drillbif_sundials_libs "${DRILLBIF_${_lib}_LIBRARY}")
  endforeach()
  target_include_directories(drillbif::sundials INTERFACE "${DRILLBIF_SUNDIALS_INCLUDE_DIR}")
  target_link_libraries(drillbif::sundials INTERFACE ${_drillbif_sundials_libs})
  file(STRINGS "${DRILLBIF_SUNDIALS_INCLUDE_DIR}/sundials/sundials_config.h" _version_line
       REGEX "^#define SUNDIALS_VERSION \"[0-9.]+")
  string(REGEX MATCH "[0-9]+\\.[0-9]+\\.[0-9]+" SUNDIALS_VERSION "${_version_line}")
  if(SUNDIALS_VERSION VERSION_LESS 6)
    message(FATAL_ERROR "drillbif needs SUNDIALS >= 6, found '${SUNDIALS_VERSION}'")
  endif()
  set(DRILLBIF_SUNDIALS_HOW "find_library (${_drillbif_sundials_libs})")
endif()
message(STATUS "drillbif: SUNDIALS ${SUNDIALS_VERSION} via ${DRILLBIF_SUNDIALS_HOW}")

# --- Protobuf ----------------------------------------------------------------------------------
find_package(Protobuf REQUIRED)

# --- Command line, tests, benchmarks -----------------------------------------------------------
find_package(CLI11 REQUIRED CONFIG)
if(DRILLBIF_BUILD_TESTS)
  find_package(GTest REQUIRED CONFIG)
  include(GoogleTest)
endif()
if(DRILLBIF_BUILD_BENCH)
  find_package(benchmark REQUIRED CONFIG)
endif()

# --- Service dependencies (found now, linked by server/ in a later issue) ----------------------
# gRPC: Debian 12 ships gRPCConfig.cmake (1.51); fall back to pkg-config grpc++ if it is missing
# or does not load.
find_package(gRPC CONFIG QUIET)
add_library(drillbif::grpc INTERFACE IMPORTED GLOBAL)
if(gRPC_FOUND AND TARGET gRPC::grpc++)
  target_link_libraries(drillbif::grpc INTERFACE gRPC::grpc++)
  if(TARGET gRPC::grpc_cpp_plugin)
    set(DRILLBIF_GRPC_CPP_PLUGIN "$<TARGET_FILE:gRPC::grpc_cpp_plugin>")
  endif()
  set(DRILLBIF_GRPC_HOW "CMake config (${gRPC_DIR})")
else()
  find_package(PkgConfig REQUIRED)
  pkg_check_modules(DRILLBIF_GRPCPP REQUIRED IMPORTED_TARGET grpc++)
  target_link_libraries(drillbif::grpc INTERFACE PkgConfig::DRILLBIF_GRPCPP)
  set(gRPC_VERSION "${DRILLBIF_GRPCPP_VERSION}")
  set(DRILLBIF_GRPC_HOW "pkg-config grpc++")
endif()
if(NOT DRILLBIF_GRPC_CPP_PLUGIN)
  find_program(DRILLBIF_GRPC_CPP_PLUGIN_PROGRAM grpc_cpp_plugin REQUIRED)
  set(DRILLBIF_GRPC_CPP_PLUGIN "${DRILLBIF_GRPC_CPP_PLUGIN_PROGRAM}")
endif()
message(STATUS "drillbif: gRPC ${gRPC_VERSION} via ${DRILLBIF_GRPC_HOW}")

find_package(spdlog REQUIRED CONFIG)
find_package(SQLite3 REQUIRED)

# OpenSSL's libcrypto: SHA-256 for the service's content-addressed cache keys (libssl-dev).
find_package(OpenSSL REQUIRED COMPONENTS Crypto)

# gRPC server reflection (libgrpc++_reflection, in Debian's libgrpc++-dev).
add_library(drillbif::grpc_reflection INTERFACE IMPORTED GLOBAL)
if(TARGET gRPC::grpc++_reflection)
  target_link_libraries(drillbif::grpc_reflection INTERFACE gRPC::grpc++_reflection)
else()
  find_library(DRILLBIF_GRPCPP_REFLECTION_LIBRARY NAMES grpc++_reflection REQUIRED)
  target_link_libraries(drillbif::grpc_reflection INTERFACE "${DRILLBIF_GRPCPP_REFLECTION_LIBRARY}"
                        drillbif::grpc)
endif()

# GNU libmicrohttpd (libmicrohttpd-dev, 0.9.75; runtime package libmicrohttpd12): the REST
# gateway's HTTP/1.1 server, event-driven (epoll threads, suspend/resume), with GnuTLS for HTTPS.
# Debian ships a pkg-config file, no CMake config.
pkg_check_modules(DRILLBIF_MICROHTTPD REQUIRED IMPORTED_TARGET libmicrohttpd>=0.9.71)
add_library(drillbif::microhttpd INTERFACE IMPORTED GLOBAL)
target_link_libraries(drillbif::microhttpd INTERFACE PkgConfig::DRILLBIF_MICROHTTPD)
message(STATUS "drillbif: libmicrohttpd ${DRILLBIF_MICROHTTPD_VERSION} via pkg-config")

# libpqxx (libpqxx-dev, 6.4; runtime package libpqxx-6.4) over libpq: the PostgreSQL job store
# (server/store/postgres_job_store.h). Debian ships a pkg-config file, no CMake config.
pkg_check_modules(DRILLBIF_PQXX REQUIRED IMPORTED_TARGET libpqxx>=6.4)
add_library(drillbif::pqxx INTERFACE IMPORTED GLOBAL)
target_link_libraries(drillbif::pqxx INTERFACE PkgConfig::DRILLBIF_PQXX)
message(STATUS "drillbif: libpqxx ${DRILLBIF_PQXX_VERSION} via pkg-config")

# utf8cpp (libutfcpp-dev, header-only): UTF-8 validation and repair of request text.
find_package(utf8cpp REQUIRED CONFIG)

# prometheus-cpp (prometheus-cpp-dev, 1.0.1; runtime package libprometheus-cpp-core1.0): the
# metrics' registry and text serializer. Only the core library is linked; the package's config
# also looks for civetweb, zlib and curl (its pull and push libraries), which the -dev package
# depends on. Debian ships no version file, so the version is not checked here.
find_package(prometheus-cpp CONFIG REQUIRED)
if(NOT TARGET prometheus-cpp::core)
  message(FATAL_ERROR
          "drillbif: prometheus-cpp found (${prometheus-cpp_DIR}) without its core target")
endif()
message(STATUS "drillbif: prometheus-cpp core via CMake config (${prometheus-cpp_DIR})")

# cpp-httplib (libcpp-httplib-dev, 0.11): Debian builds it as a shared library with OpenSSL,
# zlib and Brotli support, and the header's class layouts depend on those switches, so its
# compile definitions must come with it: pkg-config gives both (Debian ships no CMake config).
find_package(PkgConfig REQUIRED)
pkg_check_modules(DRILLBIF_HTTPLIB REQUIRED IMPORTED_TARGET cpp-httplib)
add_library(drillbif::httplib INTERFACE IMPORTED GLOBAL)
target_link_libraries(drillbif::httplib INTERFACE PkgConfig::DRILLBIF_HTTPLIB)
message(STATUS "drillbif: cpp-httplib ${DRILLBIF_HTTPLIB_VERSION} via pkg-config")
