// spinner.hpp - the thesis's C++ Spinner class (Appendix A.2), header-only, over spinner.h.
//
//   #include "spinner.hpp"
//   int main() {
//       Spinner s;                          // or Spinner s(speed_norm, speed_denorm, turn_norm, diff_norm)
//       auto img = s.getImage(60);          // one row (1 x 128); getImage() = the whole frame
//       s.setSpeedAndServo(1.0, 0.1);
//       s.addData({"text line", "another"}); // debug video, right column
//       auto [x, y, z] = s.getPosition();
//   }
//
// getImage returns a cv::Mat (CV_8UC1) when OpenCV's C++ headers are available, otherwise
// spinner::Image: the part of cv::Mat a controller uses (rows, cols, data, at<uint8_t>(r, c),
// ptr<uint8_t>(r), empty(), total(), clone()), so the same source compiles either way.
// Define SPINNER_NO_OPENCV to use spinner::Image even with OpenCV installed. With OpenCV,
// addData and addNoise take CV_8UC1 Mats, regions of a larger one (img(cv::Rect(...))) too.
// usleep/sleep/nanosleep wait in simulated time (see spinner.h).
#ifndef NXPCUP_SPINNER_HPP
#define NXPCUP_SPINNER_HPP

#include <unistd.h>  // usleep, sleep: the thesis's programs got these through the ROS headers

#include <cctype>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "spinner.h"

#if !defined(SPINNER_NO_OPENCV) && defined(__has_include)
#if __has_include(<opencv2/core.hpp>)
#include <opencv2/core.hpp>
#define SPINNER_HAVE_OPENCV 1
#endif
#endif

namespace spinner {

#ifdef SPINNER_HAVE_OPENCV
using Image = cv::Mat;

inline Image make_image(int rows, int cols) { return cv::Mat(rows, cols, CV_8UC1); }
#else
// A gray 8-bit image, row-major, owning its pixels (copying copies them, like clone()).
class Image {
  public:
    int rows = 0;
    int cols = 0;
    uint8_t *data = nullptr;

    Image() = default;
    Image(int rows_, int cols_) : rows(rows_), cols(cols_), pixels_(std::size_t(rows_) * cols_) {
        data = pixels_.data();
    }
    Image(const Image &o) : rows(o.rows), cols(o.cols), pixels_(o.pixels_) { data = pixels_.data(); }
    Image(Image &&o) noexcept : rows(o.rows), cols(o.cols), pixels_(std::move(o.pixels_)) {
        data = pixels_.data();
        o.rows = o.cols = 0;
        o.data = nullptr;
    }
    Image &operator=(Image o) noexcept {
        rows = o.rows;
        cols = o.cols;
        pixels_.swap(o.pixels_);
        data = pixels_.data();
        return *this;
    }

    template <typename T = uint8_t> T &at(int row, int col) {
        return reinterpret_cast<T *>(data + std::size_t(row) * cols)[col];
    }
    template <typename T = uint8_t> const T &at(int row, int col) const {
        return reinterpret_cast<const T *>(data + std::size_t(row) * cols)[col];
    }
    template <typename T = uint8_t> T *ptr(int row = 0) {
        return reinterpret_cast<T *>(data + std::size_t(row) * cols);
    }
    template <typename T = uint8_t> const T *ptr(int row = 0) const {
        return reinterpret_cast<const T *>(data + std::size_t(row) * cols);
    }
    bool empty() const { return pixels_.empty(); }
    std::size_t total() const { return pixels_.size(); }
    Image clone() const { return *this; }
    Image row(int r) const {
        Image out(1, cols);
        std::copy(ptr(r), ptr(r) + cols, out.data);
        return out;
    }

  private:
    std::vector<uint8_t> pixels_;
};

inline Image make_image(int rows, int cols) { return Image(rows, cols); }
#endif

using NormFn = std::function<float(float, float)>;

namespace detail {
// The norm functions of the (one) Spinner of the program, called through C trampolines.
inline NormFn &norm(int i) {
    static NormFn fns[4];
    return fns[i];
}
inline double speed_norm(double a, double b) { return norm(0)(float(a), float(b)); }
inline double speed_denorm(double a, double b) { return norm(1)(float(a), float(b)); }
inline double turn_norm(double a, double b) { return norm(2)(float(a), float(b)); }
inline double diff_norm(double a, double b) { return norm(3)(float(a), float(b)); }
}  // namespace detail

}  // namespace spinner

// The thesis's API class (Appendix A.2). Units as in spinner.h; the norm functions take
// (speed, angle) in the program's units, speed first (diff_norm: normalised speed_mps,
// steer_rad -> yaw rate rad/s).
class Spinner {
  public:
    using NormFn = spinner::NormFn;

    Spinner(std::optional<NormFn> speed_norm = std::nullopt,
            std::optional<NormFn> speed_denorm = std::nullopt,
            std::optional<NormFn> turn_norm = std::nullopt,
            std::optional<NormFn> diff_norm = std::nullopt) {
        using namespace spinner::detail;
        if (speed_norm) norm(0) = *speed_norm;
        if (speed_denorm) norm(1) = *speed_denorm;
        if (turn_norm) norm(2) = *turn_norm;
        if (diff_norm) norm(3) = *diff_norm;
        spinner_configure(speed_norm ? &spinner::detail::speed_norm : nullptr,
                          speed_denorm ? &spinner::detail::speed_denorm : nullptr,
                          turn_norm ? &spinner::detail::turn_norm : nullptr,
                          diff_norm ? &spinner::detail::diff_norm : nullptr);
    }

    void setServo(float angle, std::optional<float> speed = std::nullopt) {
        if (speed) spinner_set_servo_at(angle, *speed);
        else spinner_set_servo(angle);
    }
    void setSpeed(float speed, std::optional<float> angle = std::nullopt) {
        if (angle) spinner_set_speed_at(speed, *angle);
        else spinner_set_speed(speed);
    }
    void setSpeedAndServo(float speed, float angle) { spinner_set_speed_and_servo(speed, angle); }

    // The next camera frame: the whole image (line = -1) or one row (1 x width).
    spinner::Image getImage(int line = -1, bool add_noise = true) {
        const int h = spinner_image_height(), w = spinner_image_width();
        spinner::Image img = spinner::make_image(line < 0 ? h : 1, w);
        spinner_get_image(line, add_noise ? 1 : 0, img.data, std::size_t(img.rows) * img.cols);
        return img;
    }

    float getSpeed() { return float(spinner_get_speed()); }
    std::tuple<float, float, float> getPosition() {
        double x, y, z;
        spinner_get_position(&x, &y, &z);
        return {float(x), float(y), float(z)};
    }
    double getTime() { return spinner_get_time(); }  // double: exact steps (the thesis: float)
    float getDistance(const std::string &name) { return float(spinner_get_distance(name.c_str())); }
    void setMotors(float left, float right) { spinner_set_motors(left, right); }
    // A timer interrupt: handler() every period_s of simulated time (spinner_every; a lambda
    // without captures is such a function).
    void every(double period_s, void (*handler)()) { spinner_every(period_s, handler); }
    void stopEvery(void (*handler)()) { spinner_stop_every(handler); }
    // Mask / unmask the timer interrupts (PRIMASK: spinner_disable_interrupts; held handlers run
    // once at the enable).
    void disableInterrupts() { spinner_disable_interrupts(); }
    void enableInterrupts() { spinner_enable_interrupts(); }
    bool interruptsDisabled() { return spinner_interrupts_disabled() != 0; }
    long long getEncoder(int wheel) { return spinner_get_encoder(wheel); }
    // By name, as in Python: "FL", "FR", "RL", "RR" (any case); another name throws.
    long long getEncoder(const std::string &wheel) {
        static const char *const names[] = {"FL", "FR", "RL", "RR"};
        for (int i = 0; i < 4; ++i)
            if (wheel.size() == 2 && std::toupper((unsigned char)wheel[0]) == names[i][0] &&
                std::toupper((unsigned char)wheel[1]) == names[i][1])
                return spinner_get_encoder(i);
        throw std::invalid_argument("getEncoder(\"" + wheel + "\"): expected a wheel, one of FL, FR, RL, RR");
    }
    std::tuple<float, float, float> getGyro() {
        double x, y, z;
        spinner_get_gyro(&x, &y, &z);
        return {float(x), float(y), float(z)};
    }
    std::tuple<float, float, float> getAccel() {
        double x, y, z;
        spinner_get_accel(&x, &y, &z);
        return {float(x), float(y), float(z)};
    }
    std::vector<float> getScan(const std::string &name) {
        std::vector<double> v(4096);
        v.resize(size_t(spinner_get_scan(name.c_str(), v.data(), int(v.size()))));
        return std::vector<float>(v.begin(), v.end());
    }
    std::vector<float> getScanAngles(const std::string &name) {
        std::vector<double> v(4096);
        v.resize(size_t(spinner_get_scan_angles(name.c_str(), v.data(), int(v.size()))));
        return std::vector<float>(v.begin(), v.end());
    }
    void setExposure(double seconds) { spinner_set_exposure(seconds); }
    // From the next frame on, as a timer's period register loads at its next expiry: the frame
    // in progress keeps its period and exposure (spinner_set_exposure_next_frame).
    void setExposureNextFrame(double seconds) { spinner_set_exposure_next_frame(seconds); }
    double getExposure() { return spinner_get_exposure(); }
    // The camera's SI pulses come from a free-running timer (a kit's board driver reading each
    // image out while the next integrates): a linescan camera's frames are then one exposure
    // apart, not exposure + read-out (spinner_camera_free_running).
    void cameraFreeRunning() { spinner_camera_free_running(); }
    void sleep(double seconds) { spinner_sleep(seconds); }

    void addData(const std::vector<std::string> &data) {
        std::vector<const char *> lines;
        lines.reserve(data.size());
        for (const auto &s : data) lines.push_back(s.c_str());
        spinner_add_text(lines.data(), int(lines.size()));
    }
    void addData(const spinner::Image &img) {
#ifdef SPINNER_HAVE_OPENCV
        if (!img.isContinuous()) {  // a region of a larger Mat: its rows are not adjacent
            const cv::Mat packed = img.clone();
            spinner_add_line(packed.data, packed.rows, packed.cols);
            return;
        }
#endif
        spinner_add_line(img.data, img.rows, img.cols);
    }
    void addNoise(spinner::Image &img) {
#ifdef SPINNER_HAVE_OPENCV
        if (!img.isContinuous()) {  // noise on a packed copy, written back into the region
            cv::Mat packed = img.clone();
            spinner_add_noise(packed.data, packed.rows, packed.cols);
            packed.copyTo(img);
            return;
        }
#endif
        spinner_add_noise(img.data, img.rows, img.cols);
    }

    bool recording() const { return spinner_recording() != 0; }
    int lineRow() const { return spinner_line_row(); }
    double param(const std::string &name, double default_value) {
        return spinner_param(name.c_str(), default_value);
    }
};

#endif  // NXPCUP_SPINNER_HPP
