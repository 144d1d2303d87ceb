// Being written.
#include "core/bake/sky_visibility.h"
