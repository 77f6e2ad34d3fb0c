// placeholder until the exports land
#include "digitize/rti_export.h"
