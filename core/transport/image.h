// Moved to core/io/image.h (below both transport and io); kept for includes outside core/.
#pragma once

#include "core/io/image.h"
