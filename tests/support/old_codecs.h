/*
 * old_codecs.h — the pre-SIMD scalar codecs (see old_codecs.c), same
 * contracts as kdr_base64_encode / kdr_base64_decode / kdr_format_float.
 */
#ifndef KDR_OLD_CODECS_H
#define KDR_OLD_CODECS_H

#include <stddef.h>

size_t old_base64_encode(const void *src, size_t n, char *dst);
int old_base64_decode(const char *src, size_t n, void *dst, size_t *out_len,
                      size_t *err_offset);
size_t old_format_float(float f, char *dst);

#endif
