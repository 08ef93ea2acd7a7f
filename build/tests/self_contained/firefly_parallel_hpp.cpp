#include <firefly/parallel.hpp>
#include <firefly/parallel.hpp>  // include guard
int firefly_parallel_hpp_tu() { return 0; }
