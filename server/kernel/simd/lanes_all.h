/* The one list of lane sources, compiled once per ISA: each
 * simd/lanes_<isa>.c defines
 *   W           float lanes (double lanes: W / 2)
 *   SIMD_FN     the storage and target attributes of every helper
 *   LANES_ATTR  the target attribute of the entry points
 *   VSQRT(x), VSQRT_D(x)  the ISA's packed square roots
 *   ISA_SUFFIX  the entry points' suffix: LANES_FN(f) is f_<isa>
 * then includes this file. The machinery's lanes are here in simd/; a
 * plugin's lanes sit beside the plugin (one line each below), and the
 * plugin dispatches them (simd.h SIMD_DISPATCH). */
#define LANES_CAT2(a, b) a##_##b
#define LANES_CAT(a, b)  LANES_CAT2(a, b)
#define LANES_FN(f)      LANES_CAT(f, ISA_SUFFIX)

#include "lanes.h"
#include "warp_lanes.h"

#include "../bsdfs/fresnel_lanes.h"
#include "../bsdfs/microfacet_lanes.h"
#include "../bsdfs/rpv_lanes.h"
#include "../integrators/cull_lanes.h"
#include "../media/layered_lanes.h"
#include "../sensors/perspective_lanes.h"
#include "../sensors/sensor_common_lanes.h"
