#include <firefly/pipeline.hpp>
#include <firefly/pipeline.hpp>  // include guard
int firefly_pipeline_hpp_tu() { return 0; }
