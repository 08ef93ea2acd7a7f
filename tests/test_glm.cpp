#include <firefly/glm.hpp>

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <vector>

#include "catch.hpp"

using namespace firefly;

TEST_CASE("views over glm::vec3 and glm::vec4", "[image_view][glm]") {
    std::vector<glm::vec3> rgb(4 * 2, glm::vec3(0.0f));
    rgb[5] = glm::vec3(1, 2, 3);
    auto v = make_glm_view(rgb.data(), 4, 2);
    REQUIRE(v.ok());
    CHECK(v->channels() == 3);
    CHECK((*v)(1, 1, 2) == 3.0f);
    (*v)(3, 0, 0) = 9.0f;
    CHECK(rgb[3].x == 9.0f);

    std::vector<glm::vec4> rgba(3 * 3, glm::vec4(0.5f));
    rgba[4].w = 0.0f;
    auto w = make_glm_view(static_cast<const glm::vec4*>(rgba.data()), 3, 3);
    REQUIRE(w.ok());
    CHECK(w->channels() == 4);
    auto alpha = w->channel_range(3, 1);
    REQUIRE(alpha.ok());
    CHECK((*alpha)(1, 1) == 0.0f);
    CHECK((*alpha)(0, 0) == 0.5f);

    std::vector<glm::dvec3> d(2, glm::dvec3(1e300));
    auto dv = make_glm_view(d.data(), 2, 1);
    REQUIRE(dv.ok());
    CHECK((*dv)(1, 0, 1) == 1e300);
}
