// Pixy2.h - the Pixy2 library's C++ API (Pixy2, pixy.line) on the simulated car.
//
// The names of the Pixy2 Arduino library (docs.pixycam.com, "Line tracking API" and
// "General API"): a team's code that does
//
//     Pixy2 pixy;
//     pixy.init();
//     pixy.line.getMainFeatures();
//     if (pixy.line.numVectors) steer(pixy.line.vectors[0].m_x1 - 39);
//
// builds and runs unchanged with `simrunner drive follower.cpp --car examples/pixy2_car.toml`.
// Only the line-tracking program is emulated (docs/pixy2.md says what is and is not);
// print() writes to stdout. Built on the C API of pixy2_line.h (same layouts).
#ifndef NXPCUP_PIXY2_HPP
#define NXPCUP_PIXY2_HPP

#include <cstdint>
#include <cstdio>

#include "pixy2_line.h"

struct Vector {
    uint8_t m_x0, m_y0, m_x1, m_y1, m_index, m_flags;
    void print() const {
        std::printf("vector: (%d %d) (%d %d) index: %d flags %d\n", m_x0, m_y0, m_x1, m_y1, m_index, m_flags);
    }
};

struct IntersectionLine {
    uint8_t m_index, m_reserved;
    int16_t m_angle;
};

struct Intersection {
    uint8_t m_x, m_y, m_n, m_reserved;
    IntersectionLine m_intLines[LINE_MAX_INTERSECTION_LINES];
    void print() const {
        std::printf("intersection: (%d %d)\n", m_x, m_y);
        for (int i = 0; i < m_n; i++)
            std::printf("  %d: index: %d angle: %d\n", i, m_intLines[i].m_index, m_intLines[i].m_angle);
    }
};

struct Barcode {
    uint8_t m_x, m_y, m_flags, m_code;
    void print() const { std::printf("barcode: (%d %d), val: %d flags: %d\n", m_x, m_y, m_code, m_flags); }
};

static_assert(sizeof(Vector) == sizeof(pixy2_vector), "Vector layout");
static_assert(sizeof(Intersection) == sizeof(pixy2_intersection), "Intersection layout");
static_assert(sizeof(Barcode) == sizeof(pixy2_barcode), "Barcode layout");

class Pixy2Line {
public:
    int8_t getMainFeatures(uint8_t features = LINE_ALL_FEATURES, bool wait = true) {
        return take(pixy2_line_get_main_features(features, wait, &f_), features);
    }
    int8_t getAllFeatures(uint8_t features = LINE_ALL_FEATURES, bool wait = true) {
        return take(pixy2_line_get_all_features(features, wait, &f_), features);
    }
    int8_t setMode(uint8_t mode) { return pixy2_line_set_mode(mode); }
    int8_t setNextTurn(int16_t angle) { return pixy2_line_set_next_turn(angle); }
    int8_t setDefaultTurn(int16_t angle) { return pixy2_line_set_default_turn(angle); }
    int8_t setVector(uint8_t index) { return pixy2_line_set_vector(index); }
    int8_t reverseVector() { return pixy2_line_reverse_vector(); }

    uint8_t numVectors = 0;
    Vector *vectors = nullptr;
    uint8_t numIntersections = 0;
    Intersection *intersections = nullptr;
    uint8_t numBarcodes = 0;
    Barcode *barcodes = nullptr;

private:
    int8_t take(int8_t result, uint8_t) {
        if (result == PIXY_RESULT_BUSY) return result;
        numVectors = f_.numVectors;
        vectors = reinterpret_cast<Vector *>(f_.vectors);
        numIntersections = f_.numIntersections;
        intersections = reinterpret_cast<Intersection *>(f_.intersections);
        numBarcodes = f_.numBarcodes;
        barcodes = reinterpret_cast<Barcode *>(f_.barcodes);
        return result;
    }
    pixy2_line_features f_{};
};

extern "C" int spinner_image_width(void);
extern "C" int spinner_image_height(void);

class Pixy2 {
public:
    int8_t init(uint32_t = 0) {
        int8_t r = pixy2_init();
        frameWidth = (uint16_t)spinner_image_width();  // (the frame's size, known: no request of its own)
        frameHeight = (uint16_t)spinner_image_height();
        return r;
    }
    int8_t changeProg(const char *prog) { return pixy2_change_prog(prog); }
    int8_t getResolution() { return pixy2_get_resolution(&frameWidth, &frameHeight); }
    int8_t setCameraBrightness(uint8_t brightness) { return pixy2_set_camera_brightness(brightness); }
    int8_t setLamp(uint8_t upper, uint8_t lower) { return pixy2_set_lamp(upper, lower); }

    Pixy2Line line;
    uint16_t frameWidth = 0, frameHeight = 0;
};

#endif  // NXPCUP_PIXY2_HPP
