// The persistent pool behind executor::threads(n): every index once, the same threads reused,
// concurrent callers, a clean shutdown, and detector outputs identical to serial.
#include <firefly/firefly.hpp>
#include <firefly/sim/scene.hpp>

#include <atomic>
#include <cfloat>
#include <limits>
#include <cstring>
#include <chrono>
#include <mutex>
#include <new>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "catch.hpp"

using namespace firefly;

namespace {

// Runs count tasks and checks each index ran exactly once.
bool each_once(const executor& e, std::size_t count) {
    std::vector<std::atomic<int>> hits(count);
    for (auto& h : hits) h.store(0);
    e.run(count, [&](std::size_t i) { hits[i].fetch_add(1); });
    for (auto& h : hits)
        if (h.load() != 1) return false;
    return true;
}

struct cleaned {
    sim::frame f;
    std::vector<std::uint8_t> mask[2];
    frame_report r;
};

cleaned clean_with(const sim::scene& s, executor e) {
    cleaned c{sim::simulate(s), {}, {}};
    half_buffer<float> h[2];
    image_view<std::uint8_t> m[2];
    for (int i = 0; i < 2; ++i) {
        h[i].color = *make_image_view(c.f.color[i].data(), c.f.width, c.f.height, 3);
        h[i].variance = *make_image_view(c.f.variance[i].data(), c.f.width, c.f.height, 3);
        c.mask[i].assign(c.f.pixels(), 0);
        m[i] = *make_image_view(c.mask[i].data(), c.f.width, c.f.height, 1);
    }
    detector d(detector_options{}, std::move(e));
    c.r = d.process(h[0], h[1], m[0], m[1]);
    return c;
}

bool same_bytes(const cleaned& a, const cleaned& b) {
    for (int i = 0; i < 2; ++i) {
        if (std::memcmp(a.f.color[i].data(), b.f.color[i].data(), a.f.color[i].size() * 4) != 0) return false;
        if (std::memcmp(a.f.variance[i].data(), b.f.variance[i].data(), a.f.variance[i].size() * 4) != 0) return false;
        if (a.mask[i] != b.mask[i]) return false;
    }
    return true;
}

}  // namespace

TEST_CASE("threads(n) runs every index exactly once", "[parallel]") {
    for (unsigned n : {1u, 2u, 3u, 8u}) {
        const executor e = executor::threads(n);
        for (std::size_t count : {0, 1, 2, 3, 7, 64, 1000}) CHECK(each_once(e, count));
    }
}

// unsigned(-1), "all" as some configurations write it: at most 1024 threads (it reserved 4
// billion workers, which ended the program built without exceptions).
TEST_CASE("threads(n) past 1024 runs on 1024 threads", "[parallel]") {
    const executor e = executor::threads(static_cast<unsigned>(-1));
    std::mutex m;
    std::set<std::thread::id> ids;
    for (int call = 0; call < 2; ++call)
        e.run(4096, [&](std::size_t) {
            std::lock_guard<std::mutex> l(m);
            ids.insert(std::this_thread::get_id());
        });
    CHECK(ids.size() <= 1024);
    CHECK(each_once(e, 5000));
}

TEST_CASE("threads(n) reuses the same threads across calls", "[parallel]") {
    for (unsigned n : {2u, 4u}) {
        const executor e = executor::threads(n);
        std::mutex m;
        std::set<std::thread::id> ids;
        for (int call = 0; call < 100; ++call) {
            e.run(16, [&](std::size_t) {
                // A little work so that the workers get a share.
                volatile double x = 0;
                for (int k = 0; k < 2000; ++k) x = x + k;
                std::lock_guard<std::mutex> l(m);
                ids.insert(std::this_thread::get_id());
            });
        }
        CHECK(ids.size() <= n);
        CHECK(ids.count(std::this_thread::get_id()) == 1);  // the caller takes part
    }
}

TEST_CASE("copies share one pool and outlive the original", "[parallel]") {
    executor copy;
    {
        const executor e = executor::threads(3);
        CHECK(each_once(e, 50));
        copy = e;
    }
    CHECK(!copy.is_serial());
    CHECK(each_once(copy, 50));
}

TEST_CASE("run() from two threads at once on one executor", "[parallel]") {
    const executor e = executor::threads(2);
    std::atomic<bool> ok[2] = {{true}, {true}};
    auto caller = [&](int c) {
        for (int k = 0; k < 200; ++k)
            if (!each_once(e, 37)) ok[c] = false;
    };
    std::thread a(caller, 0), b(caller, 1);
    a.join();
    b.join();
    CHECK(ok[0].load());
    CHECK(ok[1].load());
}

TEST_CASE("a task may call run() on its own executor", "[parallel]") {
    const executor e = executor::threads(2);
    std::atomic<int> inner{0};
    e.run(4, [&](std::size_t) { e.run(5, [&](std::size_t) { inner.fetch_add(1); }); });
    CHECK(inner.load() == 20);
}

TEST_CASE("the pool is destroyed cleanly, idle or never used", "[parallel]") {
    for (int k = 0; k < 20; ++k) {
        const executor unused = executor::threads(4);
        const executor used = executor::threads(4);
        CHECK(each_once(used, 9));
        std::this_thread::sleep_for(std::chrono::microseconds(100));  // workers back asleep
    }
}

TEST_CASE("an exception thrown on a worker reaches the caller of run()", "[parallel][errors]") {
    // A worker's std::bad_alloc (a detector task allocates) called std::terminate: the Python
    // module aborted the interpreter where it raises MemoryError on the calling thread.
    const executor e = executor::threads(4);
    const std::thread::id caller = std::this_thread::get_id();
    std::atomic<bool> worker_ran{false};
    auto throw_on_worker = [&](std::size_t) {
        if (std::this_thread::get_id() != caller) {
            worker_ran = true;
            throw std::runtime_error("worker");
        }
        // the caller waits (a bounded time) for a worker to take a task
        for (int k = 0; k < 5000 && !worker_ran; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    };
    bool caught = false;
    try {
        e.run(64, throw_on_worker);
    } catch (const std::runtime_error& x) {
        caught = std::string(x.what()) == "worker";
    }
    CHECK(worker_ran.load());
    CHECK(caught);
    CHECK(each_once(e, 100));  // the pool runs on, the exception gone with its job
    CHECK_THROWS_AS(e.run(8, [](std::size_t i) {  // on whichever thread takes task 0
                        if (i == 0) throw std::bad_alloc();
                    }),
                    std::bad_alloc);
    CHECK(each_once(e, 100));
}

TEST_CASE("the detector gives the same bytes for serial, threads(2) and threads(4)", "[parallel][pipeline]") {
    // dense30 at 320x240: past one chunk of the outlier lists (4096) and one row band (64).
    for (const char* name : {"caustics", "failed_bucket", "production", "dense30"}) {
        const bool big = std::strcmp(name, "dense30") == 0;
        const sim::scene s = sim::named_scene(name, big ? 320 : 192, big ? 240 : 128, 11);
        const cleaned serial = clean_with(s, executor::serial());
        REQUIRE(serial.r.half[0].fireflies + serial.r.half[1].fireflies > 0);
        for (unsigned n : {2u, 4u}) {
            const cleaned threaded = clean_with(s, executor::threads(n));
            CHECK(same_bytes(serial, threaded));
            CHECK(threaded.r.half[0].fireflies == serial.r.half[0].fireflies);
            CHECK(threaded.r.half[1].repaired == serial.r.half[1].repaired);
        }
    }
}

TEST_CASE("compute_stddev in row bands gives the same bits and counts for any executor", "[parallel][stddev]") {
    // 3 bands and a short last one (150 rows), with every pixel class: NaN, Inf, black, alpha 0,
    // negative variance, denormals, FLT_MAX; packed RGB (the SSE2 kernel) and planar (strided).
    const int w = 37, h = 150;
    const std::size_t n = static_cast<std::size_t>(w) * h;
    sim::detail::counter_rng rng(7, 0, 0, 0);
    std::vector<float> col(n * 3), var(n * 3), alpha(n, 1.0f);
    for (std::size_t i = 0; i < n * 3; ++i) {
        col[i] = static_cast<float>(rng.uniform() * 4.0);
        var[i] = static_cast<float>(rng.uniform() * 2.0 - 0.1);  // some negative
    }
    for (std::size_t p = 0; p < n; p += 13) col[p * 3 + 1] = std::numeric_limits<float>::quiet_NaN();
    for (std::size_t p = 5; p < n; p += 29) var[p * 3] = std::numeric_limits<float>::infinity();
    for (std::size_t p = 7; p < n; p += 17) col[p * 3] = col[p * 3 + 1] = col[p * 3 + 2] = 0.0f;
    for (std::size_t p = 3; p < n; p += 31) alpha[p] = 0.0f;
    for (std::size_t p = 11; p < n; p += 37) var[p * 3 + 2] = 1e-44f;
    for (std::size_t p = 19; p < n; p += 41) var[p * 3 + 1] = FLT_MAX;
    std::vector<float> planar(n * 3);
    for (std::size_t p = 0; p < n; ++p)
        for (std::size_t c = 0; c < 3; ++c) planar[c * n + p] = col[p * 3 + c];
    const auto cv = *make_image_view(static_cast<const float*>(col.data()), w, h, 3);
    const auto pv = *image_view<const float>::create(planar.data(), w, h, 3, 4, static_cast<std::ptrdiff_t>(w) * 4,
                                                     static_cast<std::ptrdiff_t>(n) * 4);
    const auto vv = *make_image_view(static_cast<const float*>(var.data()), w, h, 3);
    for (const bool with_alpha : {false, true}) {
        image_view<const float> a;
        if (with_alpha) a = *make_image_view(static_cast<const float*>(alpha.data()), w, h, 1);
        for (const auto& colour : {cv, pv}) {
            std::vector<float> sd0(n);
            std::vector<std::uint8_t> l0(n);
            const stddev_counts k0 = compute_stddev(colour, vv, a, variance_reduction::mean, sd0.data(), l0.data());
            REQUIRE(k0.nonfinite > 0);
            REQUIRE(k0.ignored > 0);
            REQUIRE(k0.negative_variance > 0);
            for (const executor& e : {executor::serial(), executor::threads(2), executor::threads(3)}) {
                std::vector<float> sd(n, -7.0f);
                std::vector<std::uint8_t> l(n, 0xAB);
                const stddev_counts k = compute_stddev(colour, vv, a, variance_reduction::mean, sd.data(), l.data(), e);
                CHECK(std::memcmp(sd.data(), sd0.data(), n * sizeof(float)) == 0);
                CHECK(l == l0);
                CHECK(k.valid == k0.valid);
                CHECK(k.ignored == k0.ignored);
                CHECK(k.nonfinite == k0.nonfinite);
                CHECK(k.negative_variance == k0.negative_variance);
            }
        }
    }
}
