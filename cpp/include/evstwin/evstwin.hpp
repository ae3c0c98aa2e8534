// evstwin: a physics-based digital twin of an event-based vision sensor. Umbrella header.
#pragma once

#include "config.hpp"
#include "constants.hpp"
#include "event.hpp"
#include "params.hpp"
#include "physics.hpp"
#include "pixel.hpp"
#include "readout.hpp"
#include "rng.hpp"
#include "sensor.hpp"
#include "simd.hpp"
#include "sparse_step.hpp"
#include "stamp.hpp"
#include "state.hpp"
#include "version.hpp"
