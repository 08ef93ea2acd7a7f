#include <firefly/sim/scene.hpp>
#include <firefly/sim/scene.hpp>  // include guard
int firefly_sim_scene_hpp_tu() { return 0; }
