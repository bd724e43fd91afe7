/* vec3.h: the little 3-vector algebra the examples use to set up cameras and check pixels
 * (the library takes plain float arrays; this is the examples' own). */
#ifndef RT2_EXAMPLES_VEC3_H
#define RT2_EXAMPLES_VEC3_H

#include <math.h>

typedef struct { float x, y, z; } v3;
static inline v3 v(float x, float y, float z) { v3 r = {x, y, z}; return r; }
static inline v3 add(v3 a, v3 b) { return v(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline v3 sub(v3 a, v3 b) { return v(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline v3 mul(v3 a, float s) { return v(a.x * s, a.y * s, a.z * s); }
static inline float dot(v3 a, v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline v3 cross(v3 a, v3 b) { return v(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x); }
static inline v3 norm(v3 a) { return mul(a, 1.0f / sqrtf(dot(a, a))); }
/* The point of 3 floats at p. */
static inline v3 at(const float *p) { return v(p[0], p[1], p[2]); }

#endif
