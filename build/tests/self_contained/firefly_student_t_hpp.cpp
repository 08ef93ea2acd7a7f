#include <firefly/student_t.hpp>
#include <firefly/student_t.hpp>  // include guard
int firefly_student_t_hpp_tu() { return 0; }
