/* nd_theta: the model parameters the system adapts, defined once.
 *
 * theta = (sliding friction, torsional friction, rolling friction, end-effector sphere
 * mass). Every module that stores, checks, parses, prints or fits theta uses these
 * constants, names and the one validity rule below. */
#ifndef ND_THETA_H
#define ND_THETA_H

enum { ND_TH_SLIDE = 0, ND_TH_TORSION, ND_TH_ROLL, ND_TH_MASS, ND_NTHETA };

/* Largest value any entry may take: far above any friction coefficient or end-effector
 * mass a pushing robot meets (the paper's real-robot fit reached 50 kg), low enough that
 * a corrupted number is not taken for a parameter. */
#define ND_THETA_MAX 1e4

/* Ground truth of the simulation study: MuJoCo's default frictions and a 1 kg sphere. */
extern const double nd_theta_true[ND_NTHETA];

/* Long names ("sliding friction", ...), for messages. */
extern const char *const nd_theta_name[ND_NTHETA];

/* Short names ("slide", "torsion", "roll", "mass"), for options and CSV columns. */
extern const char *const nd_theta_key[ND_NTHETA];

/* Units ("", "m", "m", "kg"): MuJoCo's torsional and rolling coefficients are lengths. */
extern const char *const nd_theta_unit[ND_NTHETA];

/* The one validity rule: every entry finite and at most ND_THETA_MAX, frictions >= 0,
 * mass > 0. Return 0, or -1 naming the first bad entry. */
int nd_theta_check(const double theta[ND_NTHETA], char *err, int errlen);

/* Parse "S,T,R,M" given to option what into theta and check it. Return 0, or -1 with a
 * message that starts with what. */
int nd_theta_parse(const char *s, const char *what, double theta[ND_NTHETA], char *err,
                   int errlen);

/* Parse a comma-separated list of short names ("slide,torsion") given to option what
 * into a bit mask (bit i: entry i). Return 0, or -1 with a message naming the word. */
int nd_theta_parse_mask(const char *s, const char *what, unsigned *mask, char *err,
                        int errlen);

/* The short names of mask's entries, comma-separated, into buf ("slide,torsion"). */
void nd_theta_mask_str(unsigned mask, char *buf, int len);

#endif
