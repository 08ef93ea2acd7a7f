#include <firefly/reconstruct.hpp>
#include <firefly/reconstruct.hpp>  // include guard
int firefly_reconstruct_hpp_tu() { return 0; }
