/* nd_release: where the sphere comes to rest when a task ends, clear of the object.
 *
 * A task ends while its last plan may still press the sphere into the object; held there,
 * the tracking controller's integral keeps pushing and the object creeps on into the next
 * task's start. So the sphere is sent back along the contact normal until its surface is
 * `clear` from the object's sides, or stays where it is when it already is that far. */
#ifndef ND_RELEASE_H
#define ND_RELEASE_H

/* The object: a box in the table plane, centre (x, y), yaw, half sides half[0..1]. */
typedef struct {
  double x, y, yaw;
  double half[2];
} nd_release_box;

/* The gap (m) between the surface of a sphere of radius r at ee[2] and the box's sides,
 * negative when they overlap, and the outward contact normal n[2] (world frame). */
double nd_release_gap(const nd_release_box *b, double r, const double ee[2], double n[2]);

/* The rest point out[2] for a sphere of radius r at ee[2], at least clear (m, >= 0) from the
 * box's sides, clamped into the keypoint box [lo, hi]. Returns how far it moves the sphere
 * (m; 0 when already clear). A centre inside the box leaves by the nearest side. */
double nd_release_target(const nd_release_box *b, double r, double clear, const double ee[2],
                         const double lo[2], const double hi[2], double out[2]);

#endif
