// flagsim: real-time simulation of flags whipped by the wind (Okamoto, Fujisawa, Miura).
// Umbrella header for C++ users: #include <flagsim/flagsim.h>, link flagsim::flagsim.
#pragma once
#include "cloth/forces.h"
#include "cloth/integrators.h"
#include "cloth/params.h"
#include "cloth/topology.h"
#include "common/errors.h"
#include "common/keyframes.h"
#include "common/parallel.h"
#include "common/types.h"
#include "scene/scene.h"
#include "scene/simulation.h"
