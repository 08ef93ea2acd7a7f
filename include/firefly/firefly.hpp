// firefly: firefly detection and removal with half buffers (Jeffery, SIGGRAPH 2018).
// The umbrella header for the core. firefly/glm.hpp (GLM views) and firefly/sim/ (the
// Monte Carlo half-buffer simulator) are opt-in and not included here.
#pragma once

#include "version.hpp"
#include "status.hpp"
#include "image_view.hpp"
#include "statistics.hpp"
#include "student_t.hpp"
#include "stddev.hpp"
#include "bound.hpp"
#include "esd.hpp"
#include "highlight.hpp"
#include "local_test.hpp"
#include "kernel.hpp"
#include "reconstruct.hpp"
#include "cross_half.hpp"
#include "dropped.hpp"
#include "implausible.hpp"
#include "parallel.hpp"
#include "pipeline.hpp"
#include "buffers.hpp"
#include "accumulator.hpp"
