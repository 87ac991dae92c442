#include "common/estimation/plane_fit.h"

#include <gtest/gtest.h>

TEST(plane_fit, Placeholder) {}
