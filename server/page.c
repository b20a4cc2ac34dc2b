/*
 * page.c — the page at /: one HTML file (server/page/index.html, its CSS
 * and JavaScript inline) turned into a C array at build time
 * (server/page/embed.cmake), so kdrayd needs no files beside it and the
 * browser nothing from outside the machine.
 */
#include <stdlib.h>
#include <string.h>

#include "server.h"

extern const unsigned char kdr_page_html[];
extern const size_t kdr_page_html_len;

void kdr_page_answer(kdr_response *out) {
    char *body = malloc(kdr_page_html_len ? kdr_page_html_len : 1);
    if (!body) {
        kdr_route_problem(out, 503, "out of memory while answering");
        out->retry_after = 1;
        return;
    }
    memcpy(body, kdr_page_html, kdr_page_html_len);
    out->status = 200;
    out->content_type = "text/html; charset=utf-8";
    out->body = body;
    out->len = kdr_page_html_len;
}
