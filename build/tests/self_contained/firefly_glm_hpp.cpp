#include <firefly/glm.hpp>
#include <firefly/glm.hpp>  // include guard
int firefly_glm_hpp_tu() { return 0; }
