#include <firefly/esd.hpp>
#include <firefly/esd.hpp>  // include guard
int firefly_esd_hpp_tu() { return 0; }
