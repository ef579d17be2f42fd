/* nd_theta: the model parameters the system adapts, defined once.
 *
 * theta = (sliding friction, torsional friction, rolling friction, end-effector sphere
 * mass; the box's mass scale and centre-of-mass shift x, y). The first ND_NTHETA_PAPER are
 * the paper's. The box's three are relative to the model's box as built, so 1, 0, 0 leave
 * it as it is: a model built from a file or from a world's own box keeps its mass and
 * centre of mass until a fit says otherwise (doc/decisions.md#box-fit). Every module that
 * stores, checks, parses, prints or fits theta uses these constants, names and the one
 * validity rule below. */
#ifndef ND_THETA_H
#define ND_THETA_H

enum {
  ND_TH_SLIDE = 0, ND_TH_TORSION, ND_TH_ROLL, ND_TH_MASS,
  ND_TH_BOX_SCALE, ND_TH_COM_X, ND_TH_COM_Y,
  ND_NTHETA
};

/* The paper's parameters, theta[0..3]; files and options of four entries hold these. */
#define ND_NTHETA_PAPER 4

/* Largest value any entry may take: far above any friction coefficient or end-effector
 * mass a pushing robot meets (the paper's real-robot fit reached 50 kg), low enough that
 * a corrupted number is not taken for a parameter. */
#define ND_THETA_MAX 1e4

/* Largest centre-of-mass shift, m, either way: half a 10 cm box. A model also refuses a
 * shift that leaves its own box (nds_theta_apply). */
#define ND_THETA_COM_MAX 0.05

/* Ground truth of the simulation study: MuJoCo's default frictions, a 1 kg sphere, the
 * box as built. */
extern const double nd_theta_true[ND_NTHETA];

/* Long names ("sliding friction", ...), for messages. */
extern const char *const nd_theta_name[ND_NTHETA];

/* Short names ("slide", "torsion", "roll", "mass", "box_scale", "com_x", "com_y"), for
 * options and CSV columns. */
extern const char *const nd_theta_key[ND_NTHETA];

/* Units ("1", "m", "m", "kg", "1", "m", "m"; "1": dimensionless, as the SI writes it):
 * MuJoCo's torsional and rolling coefficients are lengths. */
extern const char *const nd_theta_unit[ND_NTHETA];

/* 1 for an entry that may be negative (the centre-of-mass shifts), 0 for one that may not. */
int nd_theta_signed(int i);

/* The one validity rule: every entry finite; frictions in [0, ND_THETA_MAX]; the masses
 * and the box's scale in (0, ND_THETA_MAX]; the shifts in [-ND_THETA_COM_MAX,
 * ND_THETA_COM_MAX]. Return 0, or -1 naming the first bad entry. */
int nd_theta_check(const double theta[ND_NTHETA], char *err, int errlen);

/* Parse "S,T,R,M" (the box as built) or all ND_NTHETA entries, "S,T,R,M,B,X,Y", given to
 * option what into theta and check it. Return 0, or -1 with a message that starts with
 * what. */
int nd_theta_parse(const char *s, const char *what, double theta[ND_NTHETA], char *err,
                   int errlen);

/* theta's ND_NTHETA entries as "%.6g" joined by sep (", " or ","), into buf. */
void nd_theta_str(const double theta[ND_NTHETA], const char *sep, char *buf, int len);

/* Parse a comma-separated list of short names ("slide,torsion") given to option what
 * into a bit mask (bit i: entry i). Return 0, or -1 with a message naming the word. */
int nd_theta_parse_mask(const char *s, const char *what, unsigned *mask, char *err,
                        int errlen);

/* The short names of mask's entries, comma-separated, into buf ("slide,torsion"). */
void nd_theta_mask_str(unsigned mask, char *buf, int len);

#endif
