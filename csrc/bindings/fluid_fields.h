// Binds the FluidParams fields of a parameter struct deriving from FluidParams (AirParams) as
// validated Python properties: section.resolution, .cell_size, .origin, .boundary, .advection,
// .pressure, .precision, .pcg_tolerance, .pcg_max_iterations, .fans. (wind, density and viscosity
// are bound by the owner.) Defined in bind_fluid.cpp.
#pragma once
#include <pybind11/pybind11.h>

#include <string>

namespace flagsim {
struct AirParams;
struct ObstacleParams;
struct SolidParams;
}  // namespace flagsim

namespace flagsim::bindings {
void def_fluid_fields(pybind11::class_<AirParams>& cls, const std::string& section);
/// The ObstacleParams fields on SolidParams, so that their errors name "<section>.<field>" and a
/// new value is checked by SolidParams::validate (the inherited ones say "obstacle").
void def_obstacle_fields(pybind11::class_<SolidParams, ObstacleParams>& cls,
                         const std::string& section);
}  // namespace flagsim::bindings
