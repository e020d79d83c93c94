/*
 * A robot in plain C (seed 8.1): pushes its state into the primitive trajectory
 * robot_state every 100 ms, steering by the latest driving direction, and prints what
 * it reads back. The C ABI as a C program uses it: statuses, messages, handles.
 *
 *   robot_c [DOMAIN] [STEPS]     DOMAIN: a system of `esgm up` (default: in process)
 */
#define _POSIX_C_SOURCE 200809L
#include <esgm.h>

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

/* Prints what failed and leaves. */
static void check(enum esgm_status status, const char *what) {
    if (status != ESGM_OK) {
        fprintf(stderr, "robot_c: %s: %s (%s)\n", what, esgm_last_error_message(),
                esgm_status_name(status));
        exit(1);
    }
}

int main(int argc, char **argv) {
    const char *domain = argc > 1 && argv[1][0] != '\0' ? argv[1] : NULL;
    int steps = argc > 2 ? atoi(argv[2]) : 20;
    esgm_t esgm;
    check(domain ? esgm_connect(domain, &esgm) : esgm_in_process(&esgm), "connect");

    /* The robot's trajectory: made here, or found if the system declares it. */
    esgm_trajectory_t robot_state;
    enum esgm_status made = esgm_create_primitive_entity_trajectory_structure(
        esgm, "robot_state", "RobotState", &robot_state);
    if (made == ESGM_ENTITY_STRUCTURE_ALREADY_EXISTS) {
        check(esgm_get_entity_trajectory_structure(esgm, "robot_state", &robot_state),
              "get robot_state");
    } else {
        check(made, "create robot_state");
    }

    double x = 0, y = 0, dir = 90;
    for (int i = 0; i < steps; i++) {
        /* Steer by the latest driving direction, if the system computes one. */
        esgm_trajectory_t driving;
        if (esgm_get_entity_trajectory_structure(esgm, "driving_direction", &driving) == ESGM_OK) {
            esgm_sample_t latest;
            if (esgm_get_latest(driving, &latest) == ESGM_OK) {
                check(esgm_sample_get_double(latest, "dir", &dir), "read dir");
                check(esgm_sample_free(latest), "free");
            }
            check(esgm_trajectory_free(driving), "free");
        }
        x += 0.1;
        y += 0.05;
        esgm_structure_t state;
        check(esgm_structure_new("robot1", esgm_now(), esgm_now(), &state), "structure");
        check(esgm_structure_set_double(state, "x", x), "x");
        check(esgm_structure_set_double(state, "y", y), "y");
        check(esgm_structure_set_double(state, "dir", dir), "dir");
        int32_t outcome;
        check(esgm_add_blocking(robot_state, state, &outcome), "add");
        nanosleep(&(struct timespec){0, 100 * 1000 * 1000}, NULL);
    }

    esgm_sample_t last;
    check(esgm_get_latest(robot_state, &last), "get_latest");
    struct esgm_sample_info_t info;
    check(esgm_sample_info(last, &info), "info");
    double last_x;
    check(esgm_sample_get_double(last, "x", &last_x), "x");
    printf("robot_c: %d states pushed; the latest, valid at %lld, has x = %.2f\n", steps,
           (long long)info.valid_time, last_x);
    check(esgm_sample_free(last), "free");
    check(esgm_trajectory_free(robot_state), "free");
    check(esgm_free(esgm), "free");
    return 0;
}
