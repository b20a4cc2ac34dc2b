/*
 * notify.h — systemd's service notification (sd_notify(3)), written out
 * rather than linked from libsystemd: when NOTIFY_SOCKET is set (a
 * Type=notify unit), kdrayd reports READY=1 once every scene is built,
 * RELOADING=1 / READY=1 around a SIGHUP reload and STOPPING=1 at shutdown,
 * each with a STATUS= line. Without NOTIFY_SOCKET every call does nothing.
 */
#ifndef KDR_SRV_NOTIFY_H
#define KDR_SRV_NOTIFY_H

/* Sends state ("READY=1\nSTATUS=...") as one datagram; errors are ignored
 * (a manager that stopped listening is not ours to fix). */
void kdr_notify(const char *state);

#endif
