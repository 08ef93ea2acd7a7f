#include <firefly/bound.hpp>
#include <firefly/bound.hpp>  // include guard
int firefly_bound_hpp_tu() { return 0; }
