/* bench/soa_floor.c with its arithmetic and path state in double, as
 * drender shades: what precision alone costs the SoA floor (make bench). */
#define FLOOR_DOUBLE 1
#include "soa_floor.c"
