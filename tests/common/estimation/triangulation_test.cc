#include "common/estimation/triangulation.h"

#include <gtest/gtest.h>

TEST(triangulation, Placeholder) {}
