#include <firefly/image_view.hpp>
#include <firefly/image_view.hpp>  // include guard
int firefly_image_view_hpp_tu() { return 0; }
