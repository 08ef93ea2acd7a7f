#include <firefly/statistics.hpp>
#include <firefly/statistics.hpp>  // include guard
int firefly_statistics_hpp_tu() { return 0; }
