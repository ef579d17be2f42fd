/* logplay: an lcm-logger log read with LCM's own eventlog API, handed to the inputs in
 * timestamp order up to each frame's time (view.h). One event is read ahead to know
 * whether the next belongs to a later frame. */
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "view.h"

int view_log_open(view_log *l, const char *path, char *err, int errlen) {
  memset(l, 0, sizeof(*l));
  errno = 0;
  if (!(l->log = lcm_eventlog_create(path, "r"))) {
    snprintf(err, errlen, "cannot open log %s: %s", path, errno ? strerror(errno) : "unreadable");
    return -1;
  }
  if (!(l->next = lcm_eventlog_read_next_event(l->log))) {
    snprintf(err, errlen, "log %s holds no event (not an lcm-logger log?)", path);
    view_log_close(l);
    return -1;
  }
  l->t0 = l->next->timestamp;
  return 0;
}

int view_log_feed(view_log *l, view_inputs *in, int64_t t_us) {
  while (l->next && l->next->timestamp <= t_us) {
    lcm_eventlog_event_t *e = l->next;
    /* The reader NUL-terminates the channel name; the inputs refuse what does not decode. */
    if (e->datalen >= 0) view_inputs_dispatch(in, e->channel, e->data, e->datalen, e->timestamp);
    l->events++;
    l->t_last = e->timestamp;
    lcm_eventlog_free_event(e);
    l->next = lcm_eventlog_read_next_event(l->log);
  }
  return l->next != NULL;
}

void view_log_close(view_log *l) {
  if (l->next) lcm_eventlog_free_event(l->next);
  if (l->log) lcm_eventlog_destroy(l->log);
  memset(l, 0, sizeof(*l));
}
