#include <firefly/status.hpp>
#include <firefly/status.hpp>  // include guard
int firefly_status_hpp_tu() { return 0; }
