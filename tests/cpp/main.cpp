// The C++ tests' main: every test_*.cpp registers its tests (check.hpp).
#include "check.hpp"

TEST_MAIN()
