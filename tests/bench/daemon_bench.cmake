# daemon_bench: the whole `scaled` process under load (real-time replay or sim,
# N watchers, a poller): dropped frames, CPU, RSS, detector latency, poll round
# trip. Not Google Benchmark: it spawns and measures a process, using the
# daemon test harness (tests/support/daemon_harness.h). Runner:
# scripts/bench-daemon.sh; results: docs/benchmarks.md.
find_package(nlohmann_json 3 REQUIRED)
find_package(Threads REQUIRED)
add_executable(daemon_bench bench/daemon_bench.cpp)
# GTest only because the harness header includes it (its DaemonUnderTest reports
# through gtest); daemon_bench itself uses the plain process and socket helpers.
target_link_libraries(daemon_bench PRIVATE scaled_test_support scaled::drivers_base scaled_warnings
                      nlohmann_json::nlohmann_json GTest::gtest Threads::Threads)
target_compile_definitions(daemon_bench PRIVATE SCALED_BIN="$<TARGET_FILE:scaled>")
add_dependencies(daemon_bench scaled)
