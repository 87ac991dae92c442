#include "common/estimation/triangulation.h"
