/* The two C23 entry points a UML built against glibc 2.38 or later calls (its command-line parsing), for a host
 * whose glibc is older (Debian bookworm: 2.36). Preloaded by tests/support/uml/boot.py; built by newer_uml.sh.
 * C23's strtol/strtoul also take a "0b" prefix with base 0 or 2; UML's kernel parameters never have one. */
#include <stdlib.h>

long __isoc23_strtol(const char *s, char **end, int base) { return strtol(s, end, base); }
unsigned long __isoc23_strtoul(const char *s, char **end, int base) { return strtoul(s, end, base); }
