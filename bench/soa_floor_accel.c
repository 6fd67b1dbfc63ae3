/* bench/soa_floor.c with its rays sent through drender's query layer
 * (core/accel.h) instead of straight to Embree: what that layer costs the
 * SoA floor (make bench). */
#define FLOOR_DR_ACCEL 1
#include "soa_floor.c"
