// Being written.
#include "core/bake/sun_transmittance.h"
