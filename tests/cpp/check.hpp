// A tiny self-contained test harness: CHECK records failures, main() reports and returns
// non-zero if any check failed. No framework is fetched at build time.
#pragma once

#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

namespace check {
inline int& failures() { static int n = 0; return n; }
inline std::vector<std::pair<std::string, std::function<void()>>>& registry() {
    static std::vector<std::pair<std::string, std::function<void()>>> r;
    return r;
}
struct Register {
    Register(const char* name, std::function<void()> f) { registry().emplace_back(name, std::move(f)); }
};
// Runs the tests whose registration index is part modulo parts (all of them by default), so
// that a slow build (the sanitized one) can run as several processes side by side.
inline int run_all(int part = 0, int parts = 1) {
    int tests = 0, index = -1;
    for (auto& [name, f] : registry()) {
        if (++index % parts != part) continue;
        const int before = failures();
        f();
        ++tests;
        std::printf("%s %s\n", failures() == before ? "PASS" : "FAIL", name.c_str());
    }
    std::printf("%d tests, %d failed checks\n", tests, failures());
    return failures() == 0 ? 0 : 1;
}
// main's arguments: none (every test) or --part=K/N (0 <= K < N: every N-th test from the K-th).
inline int run_main(int argc, char** argv) {
    int part = 0, parts = 1;
    for (int i = 1; i < argc; ++i) {
        char rest = 0;
        if (std::sscanf(argv[i], "--part=%d/%d%c", &part, &parts, &rest) != 2 || parts < 1 || part < 0 ||
            part >= parts) {
            std::fprintf(stderr, "usage: %s [--part=K/N] with 0 <= K < N; got %s\n", argv[0], argv[i]);
            return 2;
        }
    }
    return run_all(part, parts);
}
}  // namespace check

#define TEST(name) \
    static void name(); \
    static check::Register name##_reg(#name, name); \
    static void name()
#define CHECK(cond) \
    do { if (!(cond)) { ++check::failures(); std::printf("  %s:%d: CHECK(%s) failed\n", __FILE__, __LINE__, #cond); } } while (0)
#define CHECK_NEAR(a, b, tol) \
    do { const double _a = (a), _b = (b); if (!(std::fabs(_a - _b) <= (tol))) { ++check::failures(); \
         std::printf("  %s:%d: %s = %.17g, expected %.17g +- %g\n", __FILE__, __LINE__, #a, _a, _b, (double)(tol)); } } while (0)
#define CHECK_THROWS(stmt) \
    do { bool _t = false; try { stmt; } catch (const std::exception&) { _t = true; } \
         if (!_t) { ++check::failures(); std::printf("  %s:%d: %s did not throw\n", __FILE__, __LINE__, #stmt); } } while (0)
#define TEST_MAIN() int main(int argc, char** argv) { return check::run_main(argc, argv); }
