/* lane_tracker.h - the lane middle in one camera row (examples/line_follower.py's
 * lane_edges and LaneTracker in C), shared by line_follower.c and real_car_units.c. */
#ifndef LANE_TRACKER_H
#define LANE_TRACKER_H

#include <stdint.h>
#include <stdio.h>

#define WHITE 128            /* gray threshold: lane is white (~235), edges/floor dark */
#define MIN_CONTRAST 40      /* adaptive threshold: a row darker-to-brighter by less sees no lane */

/* The white lane run containing `guess` (else the nearest), white = brighter than `white`:
 * *left / *right are its first and last columns, -1 where the run reaches the image border
 * (that edge not in view). Returns 0 if no pixel is white (line lost). */
static inline int lane_edges(const uint8_t *row, int w, double guess, int white, int *left, int *right) {
    int g = (int)guess;
    g = g < 0 ? 0 : g > w - 1 ? w - 1 : g;
    if (row[g] <= white) {
        int r = -1, l = -1;
        for (int i = g; i < w; i++) if (row[i] > white) { r = i; break; }
        for (int i = g - 1; i >= 0; i--) if (row[i] > white) { l = i; break; }
        if (r < 0 && l < 0) return 0;
        g = (l < 0 || (r >= 0 && r - g <= g - l)) ? r : l;
    }
    int a = -1, b = -1;
    for (int i = g - 1; i >= 0; i--) if (row[i] <= white) { a = i; break; }
    for (int i = g; i < w; i++) if (row[i] <= white) { b = i; break; }
    *left = a >= 0 ? a + 1 : -1;
    *right = b >= 0 ? b - 1 : -1;
    return 1;
}

struct lane {           /* the lane middle in one image row, remembered between frames */
    double half, centre, lane_px;
    int left, right, seen, at_crossing;
    int white;          /* gray threshold of the next row (WHITE unless the caller sets it) */
};

/* Adaptive threshold: half-way between the row's darkest and brightest pixel (255, nothing
 * white, when they differ by less than MIN_CONTRAST). */
static inline int row_threshold(const uint8_t *row, int w) {
    int lo = 255, hi = 0;
    for (int i = 0; i < w; i++) { if (row[i] < lo) lo = row[i]; if (row[i] > hi) hi = row[i]; }
    return hi - lo >= MIN_CONTRAST ? (lo + hi) / 2 : 255;
}

/* Lateral error in half-image units, + = the lane middle is right of the car. */
static inline double lane_error(struct lane *t, const uint8_t *row, int w) {
    t->seen = lane_edges(row, w, t->centre, t->white, &t->left, &t->right);
    if (!t->seen) t->left = t->right = -1;
    t->at_crossing = t->seen && t->left < 0 && t->right < 0;
    if (t->left >= 0 && t->right >= 0) {
        t->lane_px = 0.9 * t->lane_px + 0.1 * (t->right - t->left);
        t->centre = 0.5 * (t->left + t->right);
    } else if (t->left >= 0) {
        t->centre = t->left + 0.5 * t->lane_px;
    } else if (t->right >= 0) {
        t->centre = t->right - 0.5 * t->lane_px;
    } else if (t->at_crossing) {
        t->centre = t->half;
    }
    return (t->centre - t->half) / t->half;
}

static inline struct lane lane_start(int width_px) {
    struct lane t = {width_px / 2.0, width_px / 2.0, (double)width_px, -1, -1, 0, 0, WHITE};
    return t;
}

/* A column as Python prints it: the number, or None (-1: not in view). */
static inline const char *lane_px_text(int column, char buf[16]) {
    if (column < 0) return "None";
    snprintf(buf, 16, "%d", column);
    return buf;
}

#endif
