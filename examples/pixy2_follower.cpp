// A Pixy2 line follower in C++: the twin of examples/pixy2_follower.py (read its docstring for
// the method), written against the Pixy2 library's own API (Pixy2.h).
//
// Run it:  simrunner drive examples/pixy2_follower.cpp --car examples/pixy2_car.toml [--video run.mp4]
//
// Parameters (--param NAME=VALUE): v_max, v_min (m/s), lookahead (m).
#include <Pixy2.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <tuple>
#include <vector>

#include "spinner.hpp"

namespace {

constexpr double GRID_W = 79, GRID_H = 52;  // the Pixy2's line grid
constexpr double CAM_HEIGHT_M = 0.30, CAM_PITCH_RAD = 0.60, CAM_FORWARD_M = 0.20;  // pixy2_car.toml
constexpr double HFOV_RAD = 60.0 * M_PI / 180.0;
constexpr double WHEELBASE_M = 0.175;
constexpr double HALF_LANE_M = 0.265;   // lane centre to an edge line's centre
constexpr double MIN_GAP_M = 0.35, NEAR_M = 0.9, LOOKAHEAD_M = 0.45, SMOOTH = 0.5;
constexpr double MAX_TURN_RAD = 2.0, FAR_EXTRA_M = 0.40, TIGHT_RADIUS_M = 0.6;
constexpr double V_MAX_MPS = 2.2, V_MIN_MPS = 1.2, STEER_LIMIT_RAD = 0.40;
constexpr int SLOW_CODE = 1, FAST_CODE = 2;  // barcodes: a slow zone starts / ends
const double F_PX = (GRID_W / 2.0) / std::tan(HFOV_RAD / 2.0);

struct P { double x, y; };  // on the floor: ahead, left (m)

// Grid point -> floor point from the camera (none above the horizon).
std::optional<P> to_floor(double x, double y) {
    double u = (x + 0.5 - GRID_W / 2.0) / F_PX, v = (y + 0.5 - GRID_H / 2.0) / F_PX;
    double down = std::sin(CAM_PITCH_RAD) + v * std::cos(CAM_PITCH_RAD);
    if (down <= 1e-6) return std::nullopt;
    double t = CAM_HEIGHT_M / down;
    return P{t * (std::cos(CAM_PITCH_RAD) - v * std::sin(CAM_PITCH_RAD)), -t * u};
}

double bend_rad(const Vector &a, const Vector &b) {
    auto heading = [](const Vector &v) -> std::optional<double> {
        auto p = to_floor(v.m_x0, v.m_y0), q = to_floor(v.m_x1, v.m_y1);
        if (!p || !q) return std::nullopt;
        return std::atan2(q->y - p->y, q->x - p->x);
    };
    auto ha = heading(a), hb = heading(b);
    if (!ha || !hb) return 0.0;
    double d = std::fmod(*hb - *ha + M_PI, 2.0 * M_PI);
    return (d < 0 ? d + 2.0 * M_PI : d) - M_PI;
}

// `first` and the vectors that continue it, until the line has turned MAX_TURN_RAD in all.
std::vector<Vector> edge_chain(const Vector &first, const Vector *vs, int n) {
    std::vector<Vector> chain{first};
    std::vector<int> seen{first.m_index};
    double turned = 0.0;
    for (;;) {
        const Vector &last = chain.back();
        const Vector *next = nullptr;
        for (int i = 0; i < n && !next; i++)
            if (std::find(seen.begin(), seen.end(), vs[i].m_index) == seen.end() &&
                vs[i].m_x0 == last.m_x1 && vs[i].m_y0 == last.m_y1)
                next = &vs[i];
        if (!next) return chain;
        turned += bend_rad(last, *next);
        if (std::fabs(turned) > MAX_TURN_RAD) return chain;
        chain.push_back(*next);
        seen.push_back(next->m_index);
    }
}

// The chain's floor points moved `left_m` to its left, in rear-axle coordinates.
std::vector<P> middle_points(const std::vector<Vector> &chain, double left_m) {
    std::vector<P> pts;
    for (const Vector &v : chain) {
        auto a = to_floor(v.m_x0, v.m_y0), b = to_floor(v.m_x1, v.m_y1);
        if (!a || !b) break;
        double dx = b->x - a->x, dy = b->y - a->y, n = std::hypot(dx, dy);
        if (n < 1e-9) continue;
        double ox = -dy / n * left_m + CAM_FORWARD_M, oy = dx / n * left_m;
        pts.push_back({a->x + ox, a->y + oy});
        pts.push_back({b->x + ox, b->y + oy});
    }
    return pts;
}

// Where the path leaves the circle of `radius_m` round the rear axle (pure pursuit).
std::optional<P> pursuit_point(const std::vector<P> &pts, double radius_m) {
    if (pts.size() < 2) return std::nullopt;
    std::optional<P> best;
    for (size_t k = 0; k + 1 < pts.size(); k += 2) {
        double x0 = pts[k].x, y0 = pts[k].y, dx = pts[k + 1].x - x0, dy = pts[k + 1].y - y0;
        double n = std::hypot(dx, dy);
        dx /= n, dy /= n;
        double t_foot = -(x0 * dx + y0 * dy), fx = x0 + t_foot * dx, fy = y0 + t_foot * dy;
        double gap2 = radius_m * radius_m - (fx * fx + fy * fy);
        if (gap2 <= 0.0) {
            if (k == 0) best = P{fx, fy};
            continue;
        }
        double t = t_foot + std::sqrt(gap2);
        bool first = k == 0, last = k + 2 == pts.size();
        if ((t >= 0.0 || first) && (t <= n || last)) return P{x0 + t * dx, y0 + t * dy};
    }
    return best;
}

// The vector with its tail at its lower end (the Pixy2 may have reversed it).
Vector upward(Vector v) {
    if (std::make_pair(v.m_y0, -v.m_x0) < std::make_pair(v.m_y1, -v.m_x1)) {
        std::swap(v.m_x0, v.m_x1);
        std::swap(v.m_y0, v.m_y1);
    }
    return v;
}

// The left and the right edge as vector chains (empty where there is none).
std::pair<std::vector<Vector>, std::vector<Vector>> lane_edges(const Vector *raw, int n) {
    std::vector<Vector> up;
    for (int i = 0; i < n; i++) up.push_back(upward(raw[i]));
    const Vector *vs = up.data();
    std::vector<std::tuple<double, int, P, Vector>> near;
    for (int i = 0; i < n; i++) {
        auto tail = to_floor(vs[i].m_x0, vs[i].m_y0);
        if (tail && tail->x <= NEAR_M) near.emplace_back(std::hypot(tail->x, tail->y), vs[i].m_index, *tail, vs[i]);
    }
    std::sort(near.begin(), near.end(), [](const auto &a, const auto &b) {
        return std::tie(std::get<0>(a), std::get<1>(a)) < std::tie(std::get<0>(b), std::get<1>(b));
    });
    std::vector<Vector> left, right;
    std::vector<P> points;
    for (const auto &[dist, index, tail, v] : near) {
        bool is_left = tail.y >= 0.0;
        if (!(is_left ? left : right).empty()) continue;
        bool close = false;
        for (const P &p : points) close = close || std::hypot(tail.x - p.x, tail.y - p.y) < MIN_GAP_M;
        if (close) continue;
        auto chain = edge_chain(v, vs, n);
        for (const Vector &c : chain)
            for (auto p : {to_floor(c.m_x0, c.m_y0), to_floor(c.m_x1, c.m_y1)})
                if (p) points.push_back(*p);
        (is_left ? left : right) = chain;
    }
    return {left, right};
}

double curvature(const std::vector<P> &pts) {
    double x = 0, y = 0;
    for (const P &p : pts) x += p.x, y += p.y;
    x /= pts.size(), y /= pts.size();
    return 2.0 * y / (x * x + y * y);
}

}  // namespace

int main() {
    Spinner s;
    Pixy2 pixy;
    pixy.init();
    pixy.changeProg("line");
    const double v_max = s.param("v_max", V_MAX_MPS), v_min = s.param("v_min", V_MIN_MPS);
    const double look = s.param("lookahead", LOOKAHEAD_M);
    double steer = 0.0, cap = v_max;
    for (;;) {
        pixy.line.getAllFeatures();
        for (int i = 0; i < pixy.line.numBarcodes; i++) {  // barcodes: a slow zone starts / ends
            if (pixy.line.barcodes[i].m_code == SLOW_CODE) cap = v_min;
            else if (pixy.line.barcodes[i].m_code == FAST_CODE) cap = v_max;
        }
        auto [left, right] = lane_edges(pixy.line.vectors, pixy.line.numVectors);
        std::vector<P> aims, fars;
        for (auto [chain, inward] : {std::pair{&left, -HALF_LANE_M}, std::pair{&right, HALF_LANE_M}}) {
            if (chain->empty()) continue;
            auto middle = middle_points(*chain, inward);
            if (auto p = pursuit_point(middle, look)) aims.push_back(*p);
            if (auto p = pursuit_point(middle, look + FAR_EXTRA_M)) fars.push_back(*p);
        }
        if (!aims.empty()) steer += SMOOTH * (std::atan(WHEELBASE_M * curvature(aims)) - steer);
        steer = std::clamp(steer, -STEER_LIMIT_RAD, STEER_LIMIT_RAD);
        double bend = std::fabs(steer) / STEER_LIMIT_RAD;
        if (!fars.empty()) bend = std::max(bend, std::min(1.0, std::fabs(curvature(fars)) * TIGHT_RADIUS_M));
        s.setSpeedAndServo(std::min(cap, v_max - (v_max - v_min) * bend), steer);
    }
}
