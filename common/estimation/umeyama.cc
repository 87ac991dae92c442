#include "common/estimation/umeyama.h"
