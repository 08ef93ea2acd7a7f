#include <firefly/firefly.hpp>
#include <firefly/firefly.hpp>  // include guard
int firefly_firefly_hpp_tu() { return 0; }
