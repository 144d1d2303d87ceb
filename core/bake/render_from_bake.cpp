// Being written.
#include "core/bake/render_from_bake.h"
