#include <firefly/sim/metrics.hpp>
#include <firefly/sim/metrics.hpp>  // include guard
int firefly_sim_metrics_hpp_tu() { return 0; }
