# NonlinearSession (client/nonlinear_session.h) and the API examples (client/examples/),
# against an in-process server; the example programs against a spawned nupmpc-server.
nupmpc_add_test(nonlinear_session_test SRCS client/nonlinear_session_test.cc
  DEPS nupmpc_server nupmpc_client nupmpc_instances nupmpc_api_examples_lib LABELS service)
target_compile_definitions(nonlinear_session_test PRIVATE NUPMPC_SERVER_BINARY="$<TARGET_FILE:nupmpc-server>"
  NUPMPC_API_EXAMPLE_BICYCLE="$<TARGET_FILE:nupmpc-api-example-bicycle>"
  NUPMPC_API_EXAMPLE_RACE_TRACK="$<TARGET_FILE:nupmpc-api-example-race-track>")
add_dependencies(nonlinear_session_test nupmpc-server nupmpc-api-example-bicycle nupmpc-api-example-race-track)

# The race lap through the API against the core-only example (core/examples/scenarios/race_track.h).
nupmpc_add_test(race_track_api_test SRCS client/race_track_api_test.cc
  DEPS nupmpc_server nupmpc_client nupmpc_instances nupmpc_api_examples_lib nupmpc_examples_lib LABELS service)
