// The C surface of rovib-ffi compiled as C++ (the functions keep C linkage), for the `cpp` key
// of a definition: tests/surfaces/arn2_cpp.toml.
extern "C" {
#include "../../ffi/surfaces/arn2_spline.c"
}
