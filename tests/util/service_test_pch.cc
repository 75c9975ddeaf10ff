// The translation unit that builds the service tests' precompiled header (tests/CMakeLists.txt).
