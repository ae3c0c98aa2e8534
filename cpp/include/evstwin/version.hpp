// The one place the evstwin version is written. pyproject.toml and CMakeLists.txt read it.
#pragma once

#include "config.hpp"

#define EVSTWIN_VERSION_MAJOR 0
#define EVSTWIN_VERSION_MINOR 1
#define EVSTWIN_VERSION_PATCH 0
#define EVSTWIN_VERSION "0.1.0"
