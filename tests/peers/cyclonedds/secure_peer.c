/* The Cyclone DDS 0.10 side of tests/security_interop.rs: a participant configured by CYCLONEDDS_URI
 * (with its DDS-Security section, or without one for a stranger) that reads std_msgs/String on
 * rt/chatter and answers each sample with `ack N` on rt/reply (reliable, keep-last 10). With `forge` it
 * also writes `forged N` on rt/reply every 100 ms, whoever listens. It prints `read TEXT` for each
 * sample read and `got N` at the end; it exits 2 when it read nothing.
 *
 * Usage: cyclonedds_secure_peer SECONDS [forge]   (inside the test's network namespace)
 */

#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dds/dds.h"
#include "ros2_types.h"

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s SECONDS [forge]\n", argv[0]);
    return 1;
  }
  double seconds = atof(argv[1]);
  bool forge = argc > 2 && strcmp(argv[2], "forge") == 0;
  dds_entity_t pp = dds_create_participant(0, NULL, NULL);
  if (pp < 0) {
    fprintf(stderr, "no DDS participant: %s\n", dds_strretcode(pp));
    return 1;
  }
  dds_qos_t *q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 10);
  dds_entity_t chatter = dds_create_topic(pp, &std_msgs_msg_dds__String__desc, "rt/chatter", NULL, NULL);
  dds_entity_t reply = dds_create_topic(pp, &std_msgs_msg_dds__String__desc, "rt/reply", NULL, NULL);
  dds_entity_t r = dds_create_reader(pp, chatter, q, NULL);
  dds_entity_t w = dds_create_writer(pp, reply, q, NULL);
  dds_delete_qos(q);
  if (chatter < 0 || reply < 0 || r < 0 || w < 0) {
    fprintf(stderr, "no topics, reader or writer\n");
    return 1;
  }
  long got = 0, forged = 0;
  double until = now() + seconds, next_forge = now();
  char text[64];
  while (now() < until) {
    void *samples[1] = {NULL};
    dds_sample_info_t info[1];
    int n = dds_take(r, samples, info, 1, 1);
    if (n > 0 && info[0].valid_data) {
      printf("read %s\n", ((std_msgs_msg_dds__String_ *)samples[0])->data);
      got++;
      snprintf(text, sizeof text, "ack %ld", got);
      std_msgs_msg_dds__String_ out = {.data = text};
      dds_write(w, &out);
    }
    if (n > 0) dds_return_loan(r, samples, n);
    if (forge && now() >= next_forge) {
      snprintf(text, sizeof text, "forged %ld", ++forged);
      std_msgs_msg_dds__String_ out = {.data = text};
      dds_write(w, &out);
      next_forge = now() + 0.1;
    }
    dds_sleepfor(DDS_MSECS(5));
  }
  printf("got %ld\n", got);
  fflush(stdout);
  dds_delete(pp);
  return got > 0 ? 0 : 2;
}
