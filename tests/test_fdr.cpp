// Frame-level control (fdr.hpp): Benjamini and Hochberg's published example, the step-up's
// edges (ties, a cap, m below the candidates, NaN, p below the smallest double), and the
// log tails it ranks by, at the points where they are known exactly.
#include <firefly/fdr.hpp>

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "catch.hpp"

using namespace firefly;

namespace {
std::vector<double> logs(const std::vector<double>& p) {
    std::vector<double> l;
    for (const double v : p) l.push_back(std::log(v));
    return l;
}
}  // namespace

// Benjamini and Hochberg (1995), section 4: 15 p-values from a clinical trial; at 0.05 the
// step-up keeps 4 (Bonferroni, 0.05 / 15, only 3).
TEST_CASE("fdr: Benjamini and Hochberg's example keeps the 4 smallest at 0.05", "[fdr]") {
    std::vector<double> p = logs({0.0201, 0.0001, 0.6528, 0.0004, 0.0019, 0.0095, 0.3240, 0.0278, 0.0298,
                                  0.0344, 0.0459, 0.4262, 0.5719, 0.7590, 1.0});
    const double t = bh_log_threshold(p, 15, 0.05);
    CHECK(std::exp(t) == Approx(0.0095));
    std::size_t kept = 0;
    for (const double l : p) kept += l <= t;
    CHECK(kept == 4);
    // The same candidates among more tests: the level falls with m.
    std::vector<double> again = logs({0.0001, 0.0004, 0.0019, 0.0095});
    CHECK(std::exp(bh_log_threshold(again, 15, 0.05)) == Approx(0.0095));
    again = logs({0.0001, 0.0004, 0.0019, 0.0095});
    CHECK(std::exp(bh_log_threshold(again, 150, 0.05)) == Approx(0.0004));  // 0.0019 > 3 * 0.05 / 150
}

TEST_CASE("fdr: the step-up keeps a rank that passes below ranks that do not", "[fdr]") {
    // p_(1) = 0.02 > 0.05 / 4 fails alone, but p_(2) = 0.02 <= 2 * 0.05 / 4 keeps both.
    std::vector<double> p = logs({0.02, 0.02, 0.9, 0.9});
    CHECK(std::exp(bh_log_threshold(p, 4, 0.05)) == Approx(0.02));
    p = logs({0.5, 0.6});
    CHECK(bh_log_threshold(p, 2, 0.05) == -HUGE_VAL);
}

TEST_CASE("fdr: edges: nothing, NaN, p above 1, m below the candidates, tails below 1e-308", "[fdr]") {
    std::vector<double> none;
    CHECK(bh_log_threshold(none, 100, 0.05) == -HUGE_VAL);
    std::vector<double> p = {std::log(1e-6)};
    CHECK(bh_log_threshold(p, 0, 0.05) == -HUGE_VAL);
    p = {std::log(1e-6)};
    CHECK(bh_log_threshold(p, 10, std::numeric_limits<double>::quiet_NaN()) == -HUGE_VAL);
    p = {std::numeric_limits<double>::quiet_NaN(), 3.0, std::log(1e-6)};
    const double t = bh_log_threshold(p, 3, 0.05);
    CHECK(std::exp(t) == Approx(1e-6));
    CHECK(p[1] == 0.0);  // NaN and log p > 0 count as p = 1
    p = {-2000.0, -1500.0};  // p = e^-2000: far below DBL_MIN, still ranked
    CHECK(bh_log_threshold(p, 1000000000, 0.05) == -1500.0);
    p = {-HUGE_VAL};  // p = 0 is kept, and not mistaken for "none"
    CHECK(bh_log_threshold(p, 10, 0.05) == -DBL_MAX);
    p = {std::log(0.01), std::log(0.01), std::log(0.01)};  // more candidates than tests
    CHECK(std::exp(bh_log_threshold(p, 2, 0.05)) == Approx(0.01));
}

TEST_CASE("fdr: log tails of Student's t and the normal at known points", "[fdr]") {
    CHECK(std::exp(student_t_log_upper_tail(1.0, 1.0)) == Approx(0.25).epsilon(1e-12));  // Cauchy
    for (const double t : {0.5, 3.0, 1e3, 1e8}) {  // df = 2: 1/2 (1 - t / sqrt(t^2 + 2)), without cancellation
        const double r = std::sqrt(t * t + 2.0);
        CHECK(std::exp(student_t_log_upper_tail(t, 2.0)) == Approx(1.0 / (r * (r + t))).epsilon(1e-9));
    }
    CHECK(student_t_log_upper_tail(0.0, 5.0) == Approx(std::log(0.5)));
    CHECK(std::isnan(student_t_log_upper_tail(-1.0, 5.0)));
    // Huge degrees of freedom (references: mpmath's regularized incomplete beta at 100 and 400
    // digits, from the small end, 1 - I_x(1/2, df/2) with x = t^2 / (df + t^2)): the
    // plain normal tail was 2.5e-4 off at t = 10, df = 1.001e7, and 4.8e-8 relatively at 1e9.
    // At 1e30 standard deviations, finite and tiny.
    struct point {
        double df, t, log_p;
    };
    for (const point& p : {point{1.001e7, 5.612, -18.420647226081062567}, point{1.001e7, 10.0, -53.231030430068721156},
                           point{1.001e7, 37.5, -707.61953464265571925}, point{1e8, 5.612, -18.420670916945744128},
                           point{1e8, 10.0, -53.23125965284397148}, point{1e8, 37.5, -707.66403848748432015},
                           point{1e9, 10.0, -53.23128260074409817}, point{1e10, 5.612, -18.420673525842120295},
                           point{1e10, 10.0, -53.231284895535618112}, point{1e10, 37.5, -707.66893980874762695}}) {
        INFO("df " << p.df << ", t " << p.t);
        CHECK(student_t_log_upper_tail(p.t, p.df) == Approx(p.log_p).epsilon(2e-9));
    }
    CHECK(std::isfinite(student_t_log_upper_tail(1e30, 3.0)));
    CHECK(student_t_log_upper_tail(1e30, 3.0) < -200.0);
    // Normal: exact below 30, Mills' ratio beyond (mpmath, 30 digits).
    CHECK(normal_log_upper_tail(10.0) == Approx(-53.2312851505124705783).epsilon(1e-12));
    // Past z = 30 the asymptotic series, to 1e-17 (four terms were 1.6e-10 off at 30); 50-digit
    // references.
    CHECK(normal_log_upper_tail(30.0) == Approx(-454.321243956343197107).epsilon(2e-15));
    CHECK(normal_log_upper_tail(31.0) == Approx(-484.85396362717928858).epsilon(2e-15));
    CHECK(normal_log_upper_tail(38.0) == Approx(-726.5572160188201301).epsilon(2e-15));
    CHECK(normal_log_upper_tail(40.0) == Approx(-804.608442013753788167).epsilon(2e-15));
    CHECK(normal_log_upper_tail(1000.0) == Approx(-500007.82669481218431).epsilon(2e-15));
    CHECK(normal_log_upper_tail(0.0) == Approx(std::log(0.5)));
}

// Properties: the threshold does not depend on the candidates' order, grows with alpha and
// with the candidates' count among the same tests, and keeps a set that is BH's by definition
// (every kept p passes alpha k / m at its own rank or a higher one).
TEST_CASE("fdr: order-free, monotone in alpha and in the evidence", "[fdr]") {
    std::uint64_t s = 12345;
    auto uniform = [&] {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        return (static_cast<double>(s >> 11) + 0.5) / 9007199254740992.0;
    };
    for (int trial = 0; trial < 50; ++trial) {
        std::vector<double> p;
        const std::size_t m = 1000;
        for (int i = 0; i < 40; ++i) p.push_back(std::log(uniform() * (i < 10 ? 1e-6 : 1e-2)));
        std::vector<double> a = p, b(p.rbegin(), p.rend());
        const double ta = bh_log_threshold(a, m, 0.05);
        CHECK(bh_log_threshold(b, m, 0.05) == ta);
        std::vector<double> c = p;
        CHECK(bh_log_threshold(c, m, 0.2) >= ta);
        std::vector<double> d = p;
        d.push_back(std::log(1e-9));  // one more strong candidate among the same tests
        CHECK(bh_log_threshold(d, m, 0.05) >= ta);
        if (ta == -HUGE_VAL) continue;
        std::size_t kept = 0;
        for (const double l : a) kept += l <= ta;
        CHECK(ta <= std::log(0.05 * static_cast<double>(kept) / m) + 1e-12);
    }
}
