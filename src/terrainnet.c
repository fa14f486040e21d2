/* The implementation as its own translation unit: compiled once, linked by every program. */
#define TERRAINNET_IMPLEMENTATION
#include "../terrainnet.h"
