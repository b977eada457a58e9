/* pixy2_line.h - the Pixy2's line tracking in C, on the simulated car (docs/pixy2.md).
 *
 * The Pixy2's own library is C++ (Pixy2.h, which this simulator provides too); this is the
 * same API with C names, for firmware written in C. Structures have the fields and layout of
 * the Pixy2 library's Vector, IntersectionLine, Intersection and Barcode; coordinates are in
 * the 79 x 52 line grid (x right, y down, 0,0 = top left = farthest left).
 *
 *   pixy2_line_features f;
 *   pixy2_init();
 *   for (;;) {
 *       pixy2_line_get_all_features(LINE_ALL_FEATURES, true, &f);   // waits for the next frame
 *       for (int i = 0; i < f.numVectors; i++) use(f.vectors[i].m_x0, ...);
 *   }
 *
 * Time: get_*_features with wait = true return the current frame's features when they were
 * not returned yet, else wait for the next frame (60 a second on examples/pixy2_car.toml);
 * with wait = false they let one physics step pass and return PIXY_RESULT_BUSY when no new
 * frame came. The arrays in `out` stay valid until the next get_*_features call. A value out
 * of range ends the run with an error naming the call.
 */
#ifndef NXPCUP_PIXY2_LINE_H
#define NXPCUP_PIXY2_LINE_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define LINE_VECTOR                     0x01
#define LINE_INTERSECTION               0x02
#define LINE_BARCODE                    0x04
#define LINE_ALL_FEATURES               (LINE_VECTOR | LINE_INTERSECTION | LINE_BARCODE)
#define LINE_MODE_TURN_DELAYED          0x01
#define LINE_MODE_MANUAL_SELECT_VECTOR  0x02
#define LINE_MODE_WHITE_LINE            0x80
#define LINE_FLAG_INVALID               0x02
#define LINE_FLAG_INTERSECTION_PRESENT  0x04
#define LINE_MAX_INTERSECTION_LINES     6
#define PIXY_RESULT_OK                  0
#define PIXY_RESULT_ERROR               -1
#define PIXY_RESULT_BUSY                -2

typedef struct { uint8_t m_x0, m_y0, m_x1, m_y1, m_index, m_flags; } pixy2_vector;
typedef struct { uint8_t m_index, m_reserved; int16_t m_angle; } pixy2_intersection_line;
typedef struct {
    uint8_t m_x, m_y, m_n, m_reserved;
    pixy2_intersection_line m_intLines[LINE_MAX_INTERSECTION_LINES];
} pixy2_intersection;
typedef struct { uint8_t m_x, m_y, m_flags, m_code; } pixy2_barcode;

typedef struct {
    uint8_t numVectors;
    pixy2_vector *vectors;
    uint8_t numIntersections;
    pixy2_intersection *intersections;
    uint8_t numBarcodes;
    pixy2_barcode *barcodes;
} pixy2_line_features;

/* Checks the car has a Pixy2 frame (else the run ends with the reason); PIXY_RESULT_OK. */
int8_t pixy2_init(void);
/* Only the line-tracking program is emulated: "line" (or "line_tracking") gives
 * PIXY_RESULT_OK, another program ends the run with an error naming it. */
int8_t pixy2_change_prog(const char *prog);
/* The Vector, the intersection it leads into, barcodes (getMainFeatures) / every line,
 * intersection and barcode (getAllFeatures). `features`: LINE_* bits wanted. Returns the
 * LINE_* bits of what was returned (0: nothing seen) or PIXY_RESULT_BUSY. */
int8_t pixy2_line_get_main_features(uint8_t features, bool wait, pixy2_line_features *out);
int8_t pixy2_line_get_all_features(uint8_t features, bool wait, pixy2_line_features *out);
/* Setters (no time passes); each returns PIXY_RESULT_OK. Angles in degrees, 0 = straight
 * on, + = left, -180..180. */
int8_t pixy2_line_set_mode(uint8_t mode);
int8_t pixy2_line_set_next_turn(int16_t angle);
int8_t pixy2_line_set_default_turn(int16_t angle);
int8_t pixy2_line_set_vector(uint8_t index);
int8_t pixy2_line_reverse_vector(void);
/* Exposure as brightness 0..255 (brightness / 255 of the frame period); the lamp is accepted
 * and not simulated. */
int8_t pixy2_set_camera_brightness(uint8_t brightness);
int8_t pixy2_set_lamp(uint8_t upper, uint8_t lower);
/* The frame's width and height in pixels (the library's getResolution; either pointer may be
 * NULL); PIXY_RESULT_OK. */
int8_t pixy2_get_resolution(uint16_t *width, uint16_t *height);

#ifdef __cplusplus
}
#endif
#endif /* NXPCUP_PIXY2_LINE_H */
