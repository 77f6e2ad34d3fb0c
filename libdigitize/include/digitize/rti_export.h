#pragma once
#include "digitize/rti_basis.h"
