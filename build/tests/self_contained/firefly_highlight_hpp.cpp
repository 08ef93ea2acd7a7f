#include <firefly/highlight.hpp>
#include <firefly/highlight.hpp>  // include guard
int firefly_highlight_hpp_tu() { return 0; }
