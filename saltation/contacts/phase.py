"""Grain–grain contacts inside the hydrodynamic step (SPEC §5): the contact phase of the
run loop's operator split (engine/stepping.py).

Operator split
--------------
A hydrodynamic step of length Δt (d/u*) is done in three phases, in this order:

1. **free flight** (flight.spheres.free_flight_particles): RK4 with the fluid forces, every
   grain on its own, from (x₀, u₀, ϖ₀) to (x₁, u₁, ϖ₁);
2. **contacts** (this module): the grains that can touch another one during the step are
   moved again through the step in ``n_sub`` sub-steps of h = Δt/n_sub, with the fluid
   force *held* at what the free flight gave it, plus the contact forces;
3. **bed** (flight.spheres._bed_check_body or bed.packed.packed_bed_check_particle).

Phase 2 is written as a correction to the free flight. Each grain's free-flight path in
the step is the cubic Hermite interpolant H(s), s = t/Δt ∈ [0, 1], through (x₀, u₀) and
(x₁, u₁) (spin: linear between ϖ₀ and ϖ₁); during the contact phase a grain is at
``H(s) + δx`` with velocity ``H'(s)/Δt + δu`` and spin ``ϖ(s) + δϖ``, and the deviations
obey ``dδu/dt = F_c/m``, ``dδx/dt = δu``, ``dδϖ/dt = T_c/I`` (F_c, T_c the contact force and
torque of the one contact law, physics/contact_law (LAMMPS ``gran/hooke/history``), m = 1 the grain mass,
I = 0.1) — integrated by velocity Verlet (LAMMPS ``fix nve/sphere`` order: half kick,
drift, forces at the half-kicked velocities, half kick). Hence:

- a grain that touches nothing in the step keeps the RK4 result bit for bit (δ stays 0);
- for a grain in contact, ``(x, u, ϖ) = (x₁, u₁, ϖ₁) + (δx, δu, δϖ)``: the fluid force
  acts as in free flight (held over the step, the usual CFD–DEM assumption: the contact
  lasts ~3·10⁻³ d/u*, far shorter than the drag response time), the contact impulse adds
  on top; that split's first-order error, O(Δt · |Δu_contact| · ∂a_fluid/∂u), is taken
  out for the drag after the phase (contacts/fluid_response.py: the drag of the new
  velocity from the contact on, and the Basset slip step dated at the contact).

After the phase a grain that had a contact gets the fluid re-sampled at its new position
and its **Basset history restarted**, exactly as at a bed impact (physics/history.py): a contact
changes the velocity by a finite amount in ~10⁻³ d/u*, which the Boussinesq–Basset
kernel (valid for smooth acceleration of a lone sphere) would turn into a spurious
long-lived force. A grain in a lasting contact (resting on another) restarts its history
every step, so it has none — appropriate for a grain that is not flying freely.

Contact mass: the grain's own mass (m = 1, I = 0.1, no added mass), as in the bed
rebound of SPEC §4; the dashpot is set from the restitution for that mass, so the
realised restitution is the case's e whatever the mass convention.

Which grains are sub-stepped, and from when (cost)
-------------------------------------------------
Only grains that can touch another grain in this step, and only from the earliest time
they can. With Δx = x₁ − x₀ the step's chord and b = Δt(|u₀ − ū| + |u₁ − ū|)/4 (ū = Δx/Δt)
a bound on how far the cubic bulges off it, two grains cannot touch before

    s_ij = (|x₀ᵢ − x₀ⱼ| − d − b_i − b_j) / |Δx_i − Δx_j|

(triangle inequality). A grain with s_ij ≤ 1 for another grain (or in contact now) is a
*candidate*; one that can touch no other grain in the step is not sub-stepped at all and
keeps the RK4 result and the hard bed. A candidate joins the sub-steps, with zero
deviation, at the sub-step before it can first touch a grain or the bed by a tighter
bound that keeps the chord's direction (``_chord``: the relative path is r₀ + sΔ plus a
bulge of at most (4/27)Δt(|w₀| + |w₁|), w the relative velocity less Δ/Δt, so a contact
needs the chord within d + that bulge: the smaller root of a quadratic). The triangle
inequality above counts every neighbour within |Δx_i − Δx_j| of touching as a near
contact; in the dense near-bed layer most of them move alongside or apart. Joining late
is exact: nothing acts on a grain before its first contact, so its deviation would be
exactly zero until then (the same bits as joining at s_ij). At 3.94 % (reduced sweep
case, after spin-up) the tight bound halves the grain-sub-steps: 44.7 per grain-step of
128 possible, where the coarse one took ~93.
A grain deflected by a contact can still reach a grain that had not joined: the force
kernel notices any contact with such a grain and *wakes* it at that sub-step (its
deviation is exactly zero until then), so no contact is missed on deflected paths
either. The cost of the phase is therefore n_sub × (grains close to a contact), not
n_sub × N; ``counters[SUBSTEPPED]`` counts the grain-sub-steps actually done (and "Memory
layout" below keeps their cost per grain-sub-step independent of N).

The bed in the contact phase
----------------------------
A grain that is sub-stepped has its bed contacts inside the sub-steps, as soft contacts
with fixed bed spheres of diameter d (the pair model with a fixed partner: m_eff = m,
γ_n from the **bed** restitution, the bed friction, the same k_n and k_t): a position
correction after the phase (the hard rebound moves a grain by up to ~|Δu| Δt ≈ 0.1 d)
would put it into a neighbour it is touching, and the stiff spring would turn that
overlap into a spurious kick (½ k_n δ² at δ = 0.02 d is a relative speed of ~20 u*).
Packed bed: the real bed spheres (bed/packed.py), found through its cells. Virtual bed:
when the grain's bottom first goes below the bed top, a virtual bed sphere is placed
under it along a random normal (bed.virtual.virtual_bed_normal, the same counter-based draw as
the hard virtual bed) and kept until the contact ends. The first bed contact after at
least one step off the bed counts as a bed impact and closes a jump (SPEC §6); while the
contact lasts the next jump's start moves with the grain. Such a grain joins the
sub-steps no later than the time its bottom can reach the bed top. On the packed bed a
grain that touched the bed in the previous step and whose path reaches it again is
sub-stepped too (a lasting contact: resting or rolling; with the hard rebound and
push-out below it would bounce in its hollow at ~g'Δt every step). The other grains get
the hard-sphere rebound of SPEC §4 in phase 3; a grain ending the step below the bed top
may be moved by it by up to twice its reach, which the join test adds to its distance
margin, so that such a move never pushes it into a grain it was not sub-stepped with.
Known gap: a grain woken on a deflected path after its own free path went below the bed
top starts its soft bed contact with that overlap (rare; not counted).
Known fault (README, "Known fault"): a grain resting or rolling slowly can slide off its
virtual bed sphere and sink below the bed top while that contact lasts; when it ends, the
next sphere is placed with the whole depth as overlap and throws the grain out (still
water: bed overlaps of 0.43 d, speeds of 137 √(gRd); not seen on the LES at τ*/τ*c =
0.5–1.79). Not fixed; contacts/composites.py places its spheres by the same rule.

Neighbour list (contacts.pairs.ContactList, skin s)
---------------------------------------------
Valid while no grain is more than s/2 from where the list was built, less one
displacement c common to all grains: a pair's separation changes by the difference of the
two displacements, which is that of the two with c taken out, so |Δr_ij| ≤ |e_i| + |e_j|
with e = x − x_ref − c. Before each contact phase the bound ``max(|x₀ − x_ref − c₀|,
|x₁ − x_ref − c₁|) + b`` is checked (c per axis the middle of the range of all
displacements, at x₀ and at x₁: _drift; the path minus c, linear in s, stays within its
chord's bound) and the list rebuilt at x₀ when it exceeds s/2 less LIST_ROOM, the room
kept for the deviations of the sub-steps (at 3.94 % the largest deviation in a step is
0.12 d on average, 0.18 d at most in 100 steps). Saltation carries the whole layer
downstream at ~10 u*, 0.2 d per step of 0.02 d/u*: without c the list was rebuilt every
step at 3.94 % and 2.07 %, with it every other step (200 → 101 rebuilds in 200 steps,
the same bits). A rebuild is two counting sorts (the list's cells, the search's) and
one sweep, but not cheap in the dense layer: the search (on its own cells of one
cutoff, pairs._search_cells) measures ~90 grains per grain for 20 neighbours at 3.94 %,
and the list costs ~0.65 µs per grain-step, half the RK4 step (``ContactPhase.clocks``
times every part of the phase).
If a grain moves more than s/2 in one step, the skin is widened to 2.5× its
reach, up to what the cells allow (stepping.Stepper makes them wide enough for twice the
default skin, which covers 20 u*). A grain still faster, or deflected beyond the skin, is
counted in ``overruns``; after such a step the end positions are searched afresh for
pairs in contact that the list does not hold (``missed_contacts``, reported in
summary.json; the tests require zero).
At a rebuild a widened skin goes back to the case's skin (``base_skin``, stepping.Stepper)
once 2.5× the fastest reach fits in it, the widening's margin. Before, one fast grain set the skin for
the rest of the run: the full-size 3.94 % case ran with 1.40 d after its spin-up (36
neighbours per row), while the reduced case keeps 0.96 d (20). In the reduced case a skin
of 1.4 d gives the same bits but costs 0.70–0.85 µs more per grain-step (alternated runs,
2026-12-06). From that full-size state (100 steps, one thread, the code before and after
alternated, two rounds) the contact phase over the free flight of the same run went
12.5 and 11.2 → 10.6 and 9.3, with the same end state.
The engagement test reaches further than d: a grain ending the step below the bed top
counts a margin of three reaches (its hard rebound), beyond what the list guarantees.
Its first pass uses the rows, which hold every such pair when both grains are within
half the skin of the list's reach counting that margin; a grain that is not (a fast one
hitting the bed) is searched for partners through the list's cells (_engage_unlisted).
So which grains are candidates, and which have the soft bed rather than the hard one,
does not depend on when the list was built or with what skin. (Before, only the rows
were searched: the default case gave 108 011 jumps in 10 s with the default skin and
107 215 with ``collisions.skin = 0.9``; now 107 367 with both, and with the drift taken
out of the validity test, which halves its rebuilds, 18 307 → 9 175. The old default
also had 4 % more grain–grain collisions and a largest overlap of 0.014 d against
0.012 d, as when a hard rebound pushes a grain into a neighbour it was not sub-stepped
with.) At 3.94 % about 1 % of the grains per step are searched through the cells.

Memory layout (cost linear in N)
--------------------------------
The sub-stepped grains are a small share of all (~10–25 % of a 1 % suspension) and
are scattered through the N-long grain arrays; touching a dozen such arrays per grain and
sub-step made the phase memory-bound, its cost per grain-sub-step growing with N (cache
misses: 119 → 534 ns for the kick/drift alone from N = 5 k to 100 k). So each phase first
gathers the candidates (start ≤ 1) and their list neighbours into a ``SubstepSet``:
compact arrays numbered in the list's cell order (spatial neighbours sit close in
memory), with the free-flight path of every member (x₀, u₀, ϖ₀, x₁, u₁, ϖ₁ in one
18-wide row), and for the candidates their neighbour rows (flat, remapped to member
indices, in the list's order), tangential springs, bed-contact slots, counters and jump
state. All sub-steps run on these; the changed state is scattered back once at the end
of the phase. A woken grain that was only a neighbour gets its row then, its own
neighbours appended to the set (the set grows when needed). The arithmetic and the
order of every sum are those of the per-grain arrays, so results do not depend on the
layout. Per step the phase still makes O(N) passes (reach, engagement test, the gather
scan, list rebuilds), in the list's cell order so that neighbours' rows come from cache;
the sub-steps cost O(grains sub-stepped), block by block ("Blocks"). Every member's
position at the sub-step is worked out once, in the kick-drift pass (``at``: the active
ones' current position, the others' point on their free-flight path), and the force loop
reads it for each near pair: in the dense layer a grain has many near pairs, and
evaluating the partner's path per pair cost ~10 % of the phase (3.94 %, one thread).
Within a block (within each lane of a block cut into lanes) the candidates come first,
then the members that are only their neighbours (_candidates_first): at 3.94 % two in
three members are only placed at each sub-step, and with the sub-stepped ones mixed among
them each sub-step's passes touched three times the memory. One thread: sub-steps −4 %
at 3.94 % and at 2.07 % (their time over the same run's free flight, one process switching
the order; 8 and 4 rounds); two threads at 3.94 %: no change this VM's noise could show.

Blocks (temporal blocking: cost per grain-sub-step independent of N)
-------------------------------------------------------------------
Sweeping the whole set once per sub-step streams it from memory 128 times a step once
it outgrows the cache (a 1 % suspension of 200 000 grains: ~40 000 members, tens of MB),
and the cost per grain-sub-step grew with N (200 ns at 5 000 grains, 0.6–1.6 µs at
200 000). So the set is cut into **blocks** that cannot touch each other within the
step, and each block runs all its sub-steps while it sits in cache:

- two members are put in one group when their free-flight paths come closer than
  d + 2σ during the step (``_path_gap``: |r(s)| ≥ |r₀| − |Δx_i − Δx_j| − b_i − b_j; the
  same bound as the engagement test) or they touch now; σ = BLOCK_SLACK = 0.2 d when
  one of the two may touch something on its free-flight path (start ≤ 1), else
  QUIET_SLACK = 0.05 d (``ph.block_slack``). The groups are the connected components
  (union–find over every member's list pairs), numbered in cell order; consecutive
  groups fill a block of up to BLOCK_MEMBERS = 256 members (~1 kB each: a block fits
  the 1 MB L2 cache);
- a block is sub-stepped on its own (``_run_block``): a neighbour in another block is
  treated as out of touch; grains woken on deflected paths, and the neighbours they
  bring in, belong to the block that woke them;
- afterwards ``_conflicts`` checks that no pair across blocks can have touched: for
  each such pair in an active member's row, path gap − |δx|ₘₐₓ,ᵢ − |δx|ₘₐₓ,ⱼ > d (the
  largest deviations the sub-steps produced). Then the blocked result *is* the result
  of sweeping everything at once, bit for bit (every grain's arithmetic and sums are
  the same; a pair out of touch adds nothing in either). Every pair that fails the
  check (a grain deflected by more than its slack toward another block) has its two
  groups joined, and the phase is redone, still in blocks, from the untouched grain
  arrays (``_release`` undoes the jump records written meanwhile); after MERGED_PASSES
  = 3 such passes, as one block. ``counters[BLOCKS]`` counts blocks run, ``counters[REDONE_MERGED]``
  phases redone with joined groups, ``counters[REDONE_UNBLOCKED]`` phases redone as one block.

The slacks trade group size against redone passes. The near-bed layer is dense (at
1 % solids a quarter of the grains are sub-stepped in every step), and larger slacks
join it into one giant group that no longer fits the cache; smaller ones let bed
rebounds on the tilted virtual bed (deviations ~0.2 d) cross into other blocks.
Measured at 50 000 grains, 1 % (``benchmarks/bench_scaling.py`` set-up, 40 steps):
σ = (0.25, 0.1) d: a giant group, 659 ns per grain-sub-step, no pass redone;
(0.1, 0.1): 463 ns, 13 passes redone; (0.05, 0.05): 652 ns, 61 redone;
(0.2, 0.05): 328 ns, none redone (5 000 grains: ~300 ns). Denser suspensions percolate
even so (2 % in the paper's box: 52 blocks per step, 939 ns per grain-sub-step), so a group
of more than GIANT_GROUP = 256 members is cut again with σ = (0.15, 0.05) d. (It was
(0.15, 0.02) d, measured then at 583 ns and 1 pass redone in 20 steps; (0.1, 0) d: 615 ns
but 10 redone — every redo reruns all blocks. Since the sub-steps got cheaper, at 2.07 %
on the paper's domain (52 189 grains, from a 1 s spin-up, 100 steps, one thread, two
rounds alternated, 2026-12-06) (0.15, 0.02) cut the layer into 75.6 blocks per step and
redid 50 of 100 phases: the contact phase 6.3 / 5.7× the free flight of the same run;
(0.15, 0.05): 3.9 blocks, 1 redone, 4.1 / 3.3×; (0.2, 0.05), no cut: 2.8 blocks, none
redone, 3.9 / 3.5×; (0.25, 0.05): 3.8 / 3.2×. At 3.94 % there (99 335 grains) 7.1 and
7.0× (1.89 and 1.25 blocks per step); in the reduced cases of 2.07 and 3.94 % the same
within noise.)

When even the cut leaves one giant block holding most members (more than half), the blocks
keep nothing in cache that one block would not, and their union–find is the gather's
largest part: the next UNBLOCKED_STEPS = 16 steps run as one block (``ph.unblocked``,
kept in checkpoints), then blocks are tried again. Same bits (blocks never change them),
fewer counted. In the reduced sweep's cases the largest block after the cut holds 2688 of
2744 members at 3.94 % and 986 of 1323 at 2.07 %; run as one block, the gather takes
0.54 instead of 1.03–1.15 µs per grain-step at 3.94 % (0.23 instead of 0.70–0.74 at
2.07 %) and the sub-steps the same time.

Known limit: a dense layer that percolates is one block at any size, so at full size it
does not fit in cache. At 3.94 % on the paper's domain (99 335 grains, after a 1 s
spin-up, one thread) the sub-steps cost 323 ns per grain-sub-step done against 96 in the
reduced case, and the whole step 2.4–2.6× as much per grain-step (alternated runs from
the two spun-up states, with the old 1.40 d skin). With the skin narrowed back,
``bench_dense.py --cases cases/concentration_sweep.toml --concentrations 2.07 3.94``
(2026-12-06, states of --spinup-states) gave 17.8 µs per grain-step at 3.94 % and 11.5
at 2.07 %, against 7.5 and 4.7 in the reduced cases measured ten minutes later. The work
per grain is the same at both sizes (3.94 %: 33.6 % of the grain-sub-steps are done,
64.5 % of those retired). Placing the inactive members only when a force loop first
reads them did not help: the same bits, but the sub-steps were 7–55 % slower at either
size. Making such a layer fit the cache needs temporal blocking inside it, which is not
done: at 3.94 % the layer holds ~190 members per d of x (48 000 over 255 d), so a piece
that fits the 2 MB L2 is only ~10 d long. Slabs in x at least one cutoff wide could be
sub-stepped in a skewed order (slab k to sub-step s once slabs k ± 1 reached s, each
member's place kept for two sub-steps), so that each slab's data serves many sub-steps
per load; the joins and wake-ups across slabs, retirements that read partners at another
sub-step, and the periodic x make that more than a change of loop order. Profiled
(benchmarks/profile_perf.py, 3.94 %, one thread), the growth is in the force loop:
_forces 26 % of the compiled samples in the reduced case, 48 % on the paper's domain,
against 19 % for _kick_drift in both. The rows it streams each sub-step push the
partners' data out of cache. So _near_pairs puts each row's near entries first (see
"Near pairs"), and a far pair that comes near no longer redoes the phase ("Widened rows").
From the same spun-up states, 100 steps on one thread, the code before and after each
alternated (2026-12-06): at 3.94 % the sub-steps took 11.55 / 11.50 µs per grain-step,
8.84 / 10.24 with the near entries first, 6.47 / 7.83 with widened rows as well (the whole
step 5.69 / 5.66 → 8.13 / 6.86 × 10⁴ grain-steps/s; the contact phase over the free
flight of the same run 9.97 / 9.47 → 6.70 / 6.30); at 2.07 %, one run each, 5.66 → 4.97 →
4.18 (8.77 → 10.6 × 10⁴ grain-steps/s). The same end states. In the reduced cases no
change stood out of this machine's noise. Transparent huge pages for the compiled code's
allocations (glibc's ``GLIBC_TUNABLES=glibc.malloc.hugetlb=1``; 1.9 GB of huge pages
instead of 0.55) left the contact phase over the free flight at 3.94 % on the paper's
domain at 6.99 / 6.59 against 7.05 / 6.77 (alternated, two rounds): the extra cost per
grain-sub-step at full size is not TLB misses. Fewer bytes per row entry gave no gain
there either (AMD EPYC VM, 2026-12-07, alternated with the code before): the periodic
image as a whole number of box lengths (int32, times the box length where it is used) with
``nbr`` and ``nx`` int32, 7.34 / 8.71 µs per grain-step of sub-steps against 7.31 / 7.77;
in one byte per axis (which overflows: x is unwrapped, so a pair's image counts the laps
one grain made more than the other, hundreds in a 200 s run) 8.16 → 7.77 on average over
seven pairs (−11 % to +7 %). ``nbr`` and ``nx`` stayed int32; the image is kept as its
shift, with nothing derived to keep in step with the grid. Splitting the path row so that
placing a member reads 96 of its 144 bytes gave nothing (7.46 / 8.42 against 6.69 / 8.33).
Nor did one sweep per sub-step that forces each member as soon as the members of its row
have drifted (the block kept in cell order, the members a row reaches across the periodic
x drifted first; the same bits, and a test that failed when a member's forces did not
wait for its row): on an Intel Xeon VM (Emerald Rapids: 2 MB L2, 300 MB L3; 2026-12-07),
paper's domain at 3.94 %, 60 steps from the 1 s spin-up, alternated with the code before,
the sub-steps took 5.00–5.54 µs per grain-step against 3.85–4.04, and the cell order
alone (drift, then forces) 4.46: on that machine the fusion and the lost candidates-first
order each cost time. Not kept (git history: 41a29f6, 222cd0d); not measured on a CPU with
a smaller cache, where the full-size sub-steps cost most (AMD EPYC znver5: 180 ns per
grain-sub-step done against 58 in the reduced case). One kernel per sub-step on one
thread (_kick_drift and _forces as one _sweep, the drift and force of a member shared with
the lanes) was as fast (4.03 / 4.21 against 4.04 / 4.03 there) but compiled the force code
twice: the default case's first run compiled in 68.5 / 71.1 s against 54.5 / 54.9
(benchmarks/bench_compile.py), so it went too (a3f3f99, reverted).

Near pairs. A grain's row holds every list neighbour (cutoff d + skin; in the dense layer
the skin is widened for the fast grains above it: ~21 entries per engaged grain at 3.94 %),
but only a few can come near it within the step: ~9 whose free-flight paths come within
d + 0.4 d (_path_gap), 0.1 actually touching. So the sub-steps look only at the pairs
whose paths come within d + 2σ, σ = NEAR_SLACK = 0.1 d (the *near* ones, found in the
gather by ``_near_pairs``, which moves them to the row's front, in their order, so the
sums over them keep theirs and the force loop reads the row's first ``nn`` entries only;
``nx`` keeps where each entry came from for the scatter; a pair in contact from the last
step is always near). Afterwards
``_conflicts`` checks every far pair of an active grain as it checks pairs across blocks:
path gap − |δx|ₘₐₓ,ᵢ − |δx|ₘₐₓ,ⱼ > d certifies that the pair never touched, so looking at
it would have added nothing (the same bits); otherwise the phase is redone without the
filter (``counters[REDONE_FAR]``). Measured at 3.94 % (reduced sweep, after a 0.3 s
spin-up, 100 steps, one thread): the contact phase 10.45 s without the filter, 8.33 s with
σ = 0.1 d and no phase redone; σ = 0.15: 10.1 s; 0.075: 9.1 s, 3 redone; 0.05: 15.3 s,
70 redone.

Widened rows. A redo reruns every block, and the chance that some far pair of a phase
fails the certificate grows with the grains in it: on the paper's domain at 3.94 % (99 335
grains) 34 of 100 phases were redone, at 2.07 % (52 189) 23, against none or one in the
reduced cases. But a far pair
fails it only if its two deviations add up to 2σ or more, so one of them reached σ. So a
member whose |δx|² reaches σ² (less room for rounding: _wide_dev2) in _kick_drift is
*widened* (_widen): its row and its partners' rows in its block are put back in list
order with every entry near, it is forced from that sub-step on (a retired one too: its
quiet time did not look at its far partners), and each of those pairs is looked at by
both grains from then on. Any far pair left has both members below σ, which _conflicts
certifies without computing a gap, and no phase is redone for a far pair. The same bits:
a pair looked at while apart adds nothing, and a widened row sums its terms in list order,
as the unfiltered phase does. ``counters[WIDENED]`` counts the widened members. In a
block cut into lanes (_substep_part) rows are shared between lanes: there each lane lists
its members that reached σ in its drift, and they are widened after every lane's drift,
before the forces (nothing reads a row in between), lane by lane: the same rows.

Retired members. At 3.94 % more than half of the active grain-sub-steps come after the
grain's last contact in the step (it left the bed layer, or a neighbour), or before its
next one: each still looks at its row and the bed at every sub-step and finds nothing. So
an active member that touches nothing at s (no pair, no bed sphere: zero force) *retires*
(``active`` = RETIRED) until the earliest time anything can touch it unless something else
is deflected into it (_quiet_until; ``retry`` holds that time, > 1: the rest of the step).
Unforced, its deviation moves at constant δu, so its course from s to 1 is again a cubic
Hermite (its path plus a linear δx), bounded by _chord's chord and bulge: the time is the
earlier of when that course can reach the bed top (_bed_time) and when it can come within
d of the course of a near partner that is not active (inactive or retired; _chord_touch,
the bound by which a candidate joins). It is forced again from the first sub-step at or
after that time (_kick_drift), and only if that is at least QUIET_MIN = 2 sub-steps away
does it retire at all. An active partner needs no check: it looks at the pair at every
sub-step, and if it touches a retired member (a grain deflected into it) it wakes it as it
wakes an inactive one (_wake_up): forced again from that sub-step. A retired member keeps
its drift, so its position, velocity and deviation are those it would have had active:
the same bits. Skipped are the force loop and the bed search, its kicks (its force is +0,
so they would add exactly nothing: a deviation that starts at +0 never becomes −0), and
its velocity and spin in ``cur`` (_set_place keeps only its position, which the force
loop reads as ``at``): the few that read them (a touch, _quiet_until beside it, its being
forced again) work them out from its path and deviation (_velocity_of, _spin_of: the
operations of _set_path, so the same bits). One that may not retire tries again
RETIRE_BACKOFF = 8 sub-steps later (``ph.retire_backoff``; 0: never), as does one forced
again when its time is up. The decisions read the partners' states, so they are made as
_forces goes through the members one after another; in a block cut into lanes (from
LANE_THREADS threads, "Blocks on several threads") no member retires.
``counters[RETIRED_SUBSTEPS]`` counts the retired grain-sub-steps (summary.json "timing").
At 3.94 % (reduced sweep case, after spin-up, 200 steps, one thread): retired for the rest
of the step only, 13.4 of 23.6 M grain-sub-steps retired, the sub-steps 4.33 → 3.80 µs per
grain-step; retired until a time, 15.4 M, and (with the lists below) 3.24–3.26 → 3.06–3.11;
the same end state bit for bit. Retiring on two threads measured slower: 3.45 µs decided
one member after another after the parallel force pass, 3.00 decided in the lanes
(partners in other lanes checked by their courses), against 2.75–2.83 without. Skipping a
retired member's kicks and its velocity and spin: the sub-steps over the free flight of
the same run 2.89 → 2.70 (medians of five runs each, old and new alternated, on a machine
whose speed drifted by 2×; benchmarks/bench_dense.py).

Lists instead of scans. In the dense layer a block holds ~2 750 members, of which ~400 are
forced at a sub-step, ~500 retired and the rest not sub-stepped (their ``at`` only): a
pass that goes through every member to find the forced ones pays a test per member, and
its branch, taken for a scattered third of them, is mispredicted often. So in a block not
cut into lanes the kick-drift pass, which goes through every member anyway, lists the active ones in
member order (``go``), and the force pass goes through that list; the force pass lists
the members that touched one not sub-stepped (``flagged``), and the wake-up's first round
goes through those instead of the whole block. The same members in the same order: the
same bits, and the same retirements. At 3.94 % (as above, old and new alternated) the
sub-steps 3.76–3.80 → 3.19–3.21 µs per grain-step; 2.07 %: 1.83 → 1.58. (Keeping the
sub-stepped members in lists by when they joined, so that the kick-drift pass tests
nobody either, measured slower: 3.49, the members no longer in memory order. Working out
``at`` only for members a forced one has as a near partner, by a count per member kept at
every join and retirement: 4.03–4.08, the test per member costing more than ``at``.)

Blocks on several threads. In the dense cases the near-bed layer is one giant group that
no slack cuts (3.94 %: one or two blocks per step), so blocks are not what is shared
between threads. Instead, on LANE_THREADS = 3 or more threads (``soft_contact_phase(...,
threads)``) a block of at least PARALLEL_MEMBERS candidates runs each part of each
sub-step — half kick and drift, forces, half kick — over its members in parallel, one
contiguous range of members (a *lane*) per thread (``_substep_part``); the joins and
wake-ups between the parts stay serial. A member's force is its own sum over its own row
(both grains of a pair compute it) and every other write is to its own row, so the result
is the same bits on any thread count (tests/test_collide_blocks.py).
``counters[PARALLEL_BLOCKS]`` counts such blocks (summary.json "timing"). Lanes have
neither retirement nor the lists, which save more than a second thread gives: on two
threads (reduced sweep cases after spin-up, 100 steps, lanes on and off alternated, two
rounds) the sub-steps took 3.75 and 4.28 µs per grain-step in lanes against 3.67 and 4.04
with the block on one of the threads at 3.94 %, and 2.94 and 2.86 against 2.06 and 2.14 at
2.07 %. So on two threads the sub-steps run on one (the list, the engagement test and the
free flight still run on both). Lanes that keep lists and retire members (decided after
every lane's forces, each checking the partners that may retire too) gave the same bits
but were no faster on two threads: the sub-steps over the free flight of the same run 4.88
against 3.56 (lanes without retirement) at 2.07 %, 5.06 against 4.99 at 3.94 % (one run
each on a VM whose speed drifted; why is not known: the parallel launches, ~2 µs each,
three per sub-step, are ~0.8 ms of the ~4.5 ms the sub-steps take per step at 2.07 %).
From three threads on, lanes may win: not measured (this machine has two cores).
``ph.parallel_members`` holds both thresholds.

Statistics (per grain, race-free): ``cl.collisions`` (contacts begun), ``cl.max_overlap``,
and here ``contact_substeps`` (sub-steps spent in each contact, summed) and
``overlap_sum`` (overlap summed over those sub-steps): mean contact duration in sub-steps
= Σ contact_substeps / Σ collisions, time-mean overlap = Σ overlap_sum / Σ contact_substeps.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..bed.jumps import close_jump
from ..bed.packed import bed_cell, bed_offset, bed_stencil_cell
from ..bed.virtual import virtual_bed_normal
from ..flight.path import hermite_point
from ..flight.spheres import GrainState, GrainStateRef
from ..grains.refs import as_tuple, struct_ref
from ..io.progress import wall_clock
from ..physics.contact_law import lever_torque, sphere_contact_velocity, spring_dashpot
from ..physics.history import history_mark_impact
from ..physics.rng import uniform2
from .cells import axis_span, build_cells, image_shift, min_image, stable_argsort, stencil_cells
from .pairs import (
    LEVER_RADIUS,
    ContactList,
    ContactListRef,
    hard_sphere_collisions,
    normal_damping,
    push_apart,
    rebuild,
)

__all__ = ["ContactPhase", "SubstepSet", "BedContext", "make_contact_phase", "make_bed_context", "soft_contact_phase",
           "empty_substep_set",
           "hard_contact_phase"]

BLOCK_SLACK = 0.2  # d: deviation from free flight a block allows each grain ("Blocks")
QUIET_SLACK = 0.05  # d: the same for pairs of grains that cannot touch on their free-flight paths
BLOCK_MEMBERS = 256  # members per block (~1 kB each: a block stays in a 1 MB L2 cache)
GIANT_GROUP = 256  # members: a larger group (a dense layer percolating) is cut with tighter slacks
GIANT_BLOCK_SLACK = 0.15  # d: those slacks
GIANT_QUIET_SLACK = 0.05
TOUCH_EPS = 1e-9  # relative safety of the join bounds against rounding (_first_touch)
LIST_ROOM = 0.1  # d: room kept in the skin for the sub-steps' deviations ("Neighbour list")
NEAR_SLACK = 0.1  # d: deviation each grain of a pair may have before a far pair is looked at ("Near pairs")
UNBLOCKED_STEPS = 16  # steps run as one block after the blocks came out as one giant block ("Blocks")
RETIRE_BACKOFF = 8  # sub-steps before a member that could not retire tries again ("Retired members")
QUIET_MIN = 2  # sub-steps: the least quiet time worth retiring a member for
PARALLEL_MEMBERS = 256  # candidates: a block this large runs its sub-steps on all threads ...
LANE_THREADS = 3  # ... when there are this many ("Blocks on several threads")
MERGED_PASSES = 3  # passes redone with the conflicting groups joined before one that is a single block
BC_MIN_JUMP_DURATION, BC_MIN_JUMP_HEIGHT = 7, 8  # slots of BedContext.params (bed/jumps.py)
BED_SLOTS = 4  # bed spheres one grain can touch at once (3 in a hollow of the packed layer)
ACTIVE, RETIRED, CLAIMED = 1, 2, 3  # SubstepSet.active: forced; unforced for the rest of the step; waking
FREE = -1  # an empty bed-contact slot
VIRTUAL = -2  # a slot holding a virtual bed grain

# slots of ContactPhase.counters (engine/stepping.py reports them by these names)
LIST_REBUILDS = 0  # neighbour-list rebuilds inside steps
OVERRUNS = 1  # grains that moved further than the list's skin allowed
WAKES = 2  # grains woken into a running sub-step set by a contact
SUBSTEPPED = 3  # grain-sub-steps done
MISSED = 4  # contacts found after the phase that it did not resolve
BLOCKS = 5  # independent blocks run ("Blocks")
REDONE_UNBLOCKED = 6  # phases redone as one block
REDONE_MERGED = 7  # phases redone with conflicting groups merged
PARALLEL_BLOCKS = 8  # blocks whose sub-steps ran on several threads (soft_contact_phase)
REDONE_FAR = 9  # phases redone without the near-pair filter (a far pair came near)
RETIRED_SUBSTEPS = 10  # grain-sub-steps of retired members (SUBSTEPPED counts them too; "Retired members")
WIDENED = 11  # members whose far pairs were looked at once their deviation reached the slack ("Near pairs")
N_COUNTERS = 12

# parts of soft_contact_phase whose wall time ContactPhase.clocks adds up (when profiling)
CLOCK_LIST = 0  # reach of every path, neighbour-list rebuild
CLOCK_ENGAGE = 1  # candidates and their earliest contacts (_engage)
CLOCK_GATHER = 2  # compact set, rows, near pairs, blocks (_gather)
CLOCK_SUBSTEPS = 3  # the sub-steps of every block (_run_block)
CLOCK_CONFLICTS = 4  # cross-block check and redone passes' release (_conflicts, _release)
CLOCK_SCATTER = 5  # results back to the grain arrays, missed-contact search (_scatter)
N_CLOCKS = 6
CLOCK_NAMES = ("list", "engage", "gather", "substeps", "conflicts", "scatter")  # by CLOCK_* index


class BedContext(NamedTuple):
    """The bed as the contact phase sees it: soft contacts with fixed bed spheres for the
    grains being sub-stepped (module docstring). Flat arrays only (parallel loops)."""
    params: np.ndarray  # (9,) packed (0/1), e, f, max tilt (rad), γ_n (m_eff = m), k_n, k_t, jump thresholds
    ints: np.ndarray  # (2,) int64: seed, index of the current step
    t0: np.ndarray  # (1,) start time of the current step (d/u*)
    centres: np.ndarray  # packed bed (bed.packed.PackedBed, flattened)
    box: np.ndarray
    ncell: np.ndarray
    size: np.ndarray
    cell_start: np.ndarray
    cell_count: np.ndarray
    order: np.ndarray
    slot_id: np.ndarray  # (N, S) int64 bed sphere id, VIRTUAL or FREE
    slot_c: np.ndarray  # (N, S, 3) its centre, in the grain's unwrapped frame
    slot_shear: np.ndarray  # (N, S, 3) tangential spring
    in_bed: np.ndarray  # (N,) uint8 touching the bed at the last evaluation
    last_contact: np.ndarray  # (N,) int64 last step with bed contact (shared with bed/packed.py)


def make_bed_context(n, packed: bool, pb, restitution, friction, max_tilt, kn, kt, seed, last_contact,
                     min_jump_duration=0.0, min_jump_height=0.0):
    """BedContext for n grains; pb: a bed.packed.PackedBed (any, when not packed); the
    jump thresholds as in bed/jumps.py."""
    gamma = normal_damping(restitution, kn, 1.0) if restitution > 0.0 else 2.0 * math.sqrt(kn)
    params = np.array([1.0 if packed else 0.0, restitution, friction, max_tilt, gamma, kn, kt,
                       min_jump_duration, min_jump_height])
    return BedContext(params, np.array([seed, 0], np.int64), np.zeros(1), pb.centres, pb.box, pb.ncell,
                      pb.size, pb.cell_start, pb.cell_count, pb.order, np.full((n, BED_SLOTS), FREE, np.int64),
                      np.zeros((n, BED_SLOTS, 3)), np.zeros((n, BED_SLOTS, 3)), np.zeros(n, np.uint8),
                      last_contact)


class ContactPhase(NamedTuple):
    active: np.ndarray  # (N,) uint8: sub-stepped in this step (the bed pass skips them)
    act: np.ndarray  # (N,) int64: ids of the sub-stepped grains, n_act[0] of them (cell order)
    n_act: np.ndarray  # (1,) int64
    reach: np.ndarray  # (N,) float64: D, how far the free-flight path gets from x₀
    x0pos: np.ndarray  # (N,3) start-of-step positions, for list rebuilds
    ref_bound: np.ndarray  # (N,) bound on the free-flight path's distance from the list's reference
    margin: np.ndarray  # (N,) scratch: engagement reach incl. the bed-rebound margin
    start: np.ndarray  # (N,) earliest possible contact in the step (fraction s; inf: none)
    loc: np.ndarray  # (N,) int64: a grain's row in the SubstepSet, -1 outside a contact phase
    bed_overlap_max: np.ndarray  # (N,) largest overlap with a bed sphere (d)
    contact_substeps: np.ndarray  # (N,) int64 Σ sub-steps in contact (statistics)
    overlap_sum: np.ndarray  # (N,) float64 Σ overlap over those sub-steps (d)
    counters: np.ndarray  # (N_COUNTERS,) int64, named by the slot constants above
    block_members: np.ndarray  # (1,) int64 most members per block (BLOCK_MEMBERS; "Blocks")
    block_slack: np.ndarray  # (5,) float64 σ (d) of candidates and of the other members (BLOCK_SLACK,
    #                          QUIET_SLACK), the same inside giant groups, giant group size (GIANT_*; "Blocks")
    parallel_members: np.ndarray  # (2,) int64 fewest candidates of a block run on all threads, and fewest threads
    #                               for it (PARALLEL_MEMBERS, LANE_THREADS)
    near_slack: np.ndarray  # (1,) float64 σ (d) of the near-pair filter (NEAR_SLACK; inf: no filter)
    retire_backoff: np.ndarray  # (1,) float64 RETIRE_BACKOFF (sub-steps; 0: members never retire)
    unblocked: np.ndarray  # (2,) int64 the phase runs as one block before step unblocked[0], set to
    #                        unblocked[1] (UNBLOCKED_STEPS; 0: never) steps on after one giant block ("Blocks")
    clocks: np.ndarray  # (N_CLOCKS,) s spent in each part (CLOCK_*), added up only when it has that
    #                     length (profiling; length 0: no clock is read)
    deviation: np.ndarray  # (N, 6) δx, δu at the step's end of the grains with a contact in this step
    #                        (the others' rows are stale): contacts/fluid_response.py


def make_contact_phase(n: int, block_members: int = BLOCK_MEMBERS,
                       block_slack=(BLOCK_SLACK, QUIET_SLACK, GIANT_BLOCK_SLACK, GIANT_QUIET_SLACK, GIANT_GROUP),
                       profile: bool = False) -> ContactPhase:
    """profile: add up the wall time of each part of the phase in ``clocks`` (CLOCK_*)."""
    return ContactPhase(
        np.zeros(n, np.uint8), np.zeros(n, np.int64), np.zeros(1, np.int64), np.zeros(n), np.zeros((n, 3)),
        np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n, np.int64),
        np.zeros(n), np.zeros(N_COUNTERS, np.int64), np.array([block_members], np.int64),
        np.array([float(x) for x in block_slack]), np.array([PARALLEL_MEMBERS, LANE_THREADS], np.int64),
        np.array([NEAR_SLACK]), np.array([float(RETIRE_BACKOFF)]), np.array([0, UNBLOCKED_STEPS], np.int64),
        np.zeros(N_CLOCKS if profile else 0), np.zeros((n, 6)),
    )


class SubstepSet(NamedTuple):
    """The grains of one contact phase, copied into compact arrays (module docstring,
    "Memory layout"): members 0..n[0]-1 in cell order (woken grains' neighbours appended),
    each with its free-flight path; members with a row (``has_row``) also carry their
    neighbour list (flat, ``nbr[rs : rs + rc]``, neighbours as member indices), contact
    history and the per-grain state the sub-steps change. ``gid``: the grain's id."""
    n: np.ndarray  # (1,) int64 members in use
    n_rows: np.ndarray  # (1,) int64 flat row entries in use
    gid: np.ndarray  # (C,) int64
    path: np.ndarray  # (C, 18) x₀, u₀, ϖ₀, x₁, u₁, ϖ₁ of the free flight
    cur: np.ndarray  # (C, 9) P, V, W at the current sub-step (active members)
    dev: np.ndarray  # (C, 9) deviations δx, δu, δϖ from the free-flight path
    ft: np.ndarray  # (C, 6) contact force and torque at the last evaluation
    dev_max: np.ndarray  # (C,) largest |δx|² in this step
    start: np.ndarray  # (C,) earliest possible contact (inf: not a candidate)
    active: np.ndarray  # (C,) uint8 sub-stepped from now on: 0 no, ACTIVE, RETIRED ("Retired members")
    wake: np.ndarray  # (C,) uint8 touched a member that was not active
    touched: np.ndarray  # (C,) uint8 had a contact in this step
    has_row: np.ndarray  # (C,) uint8
    queue: np.ndarray  # (C,) int64 scratch: members woken in a round
    rs: np.ndarray  # (C,) int64 first flat entry of the row
    rc: np.ndarray  # (C,) int64 neighbours in the row
    nbr: np.ndarray  # (R,) int32 neighbour (member index)
    shear: np.ndarray  # (R, 3) tangential spring
    touch: np.ndarray  # (R,) uint8
    collisions: np.ndarray  # (C,) int64 (the ContactList's counters, copied in and out)
    max_overlap: np.ndarray  # (C,)
    n_touch: np.ndarray  # (C,) int64
    contact_substeps: np.ndarray  # (C,) int64
    overlap_sum: np.ndarray  # (C,)
    bed_overlap_max: np.ndarray  # (C,)
    slot_id: np.ndarray  # (C, S) int64 (BedContext's, copied in and out)
    slot_c: np.ndarray  # (C, S, 3)
    slot_shear: np.ndarray  # (C, S, 3)
    in_bed: np.ndarray  # (C,) uint8
    last_contact: np.ndarray  # (C,) int64
    nrm: np.ndarray  # (C, 3) scratch: virtual bed normal
    impacts: np.ndarray  # (C,) int64 (GrainState's, copied in and out)
    jump_t0: np.ndarray  # (C,)
    jump_x0: np.ndarray  # (C,)
    jump_ymax: np.ndarray  # (C,)
    block: np.ndarray  # (C,) int64 the block the member is sub-stepped in ("Blocks")
    jump_n0: np.ndarray  # (C,) int64 the grain's jump_buf_n and jump_count when its row was
    jump_c0: np.ndarray  # (C,) int64 copied in (restored if the phase is redone unblocked)
    nn: np.ndarray  # (C,) int64 near entries of the row (free-flight paths within d + 2 NEAR_SLACK): its first nn
    nx: np.ndarray  # (R,) int32 where each row entry was set (_set_row): its list entry is nx − rs
    at: np.ndarray  # (C, 3) every member's position at the sub-step being evaluated (_at)
    image: np.ndarray  # (R, 3) periodic-image shift of row entry k for the step (_set_row; x is unwrapped: whole laps)
    retry: np.ndarray  # (C,) step fraction from which an active member may try to retire; a retired one is forced again
    flagged: np.ndarray  # (C,) int64 scratch: members that touched one not active, in _forces' order
    go: np.ndarray  # (C,) int64 scratch: the active members of the sub-step, in member order (_kick_drift)
    retired: np.ndarray  # (1,) int64 grain-sub-steps of the block's members while retired
    widened: np.ndarray  # (1,) int64 members whose deviation reached the near filter's slack (_widen)


# The set travels between kernels as a StructRef (grains/refs.py), made and grown only in
# compiled code; the sub-step kernels read it as the tuple above (``as_tuple``). The
# contact phase's other tuples likewise (soft_contact_phase).
SubstepSetRefType, SubstepSetRef = struct_ref(SubstepSet, __name__)
ContactPhaseRefType, ContactPhaseRef = struct_ref(ContactPhase, __name__)
BedContextRefType, BedContextRef = struct_ref(BedContext, __name__)


@njit(cache=True, no_cfunc_wrapper=True)
def _make_set(c, r):
    c = max(c, 1)
    r = max(r, 1)
    return SubstepSetRef(
        np.zeros(1, np.int64), np.zeros(1, np.int64), np.empty(c, np.int64),
        np.empty((c, 18)), np.empty((c, 9)), np.empty((c, 9)), np.empty((c, 6)), np.empty(c), np.empty(c),
        np.empty(c, np.uint8), np.empty(c, np.uint8), np.empty(c, np.uint8), np.empty(c, np.uint8),
        np.empty(c, np.int64), np.empty(c, np.int64), np.empty(c, np.int64), np.empty(r, np.int32),
        np.empty((r, 3)), np.empty(r, np.uint8), np.empty(c, np.int64), np.empty(c),
        np.empty(c, np.int64), np.empty(c, np.int64), np.empty(c), np.empty(c), np.empty((c, BED_SLOTS), np.int64),
        np.empty((c, BED_SLOTS, 3)), np.empty((c, BED_SLOTS, 3)), np.empty(c, np.uint8), np.empty(c, np.int64),
        np.empty((c, 3)), np.empty(c, np.int64), np.empty(c), np.empty(c), np.empty(c), np.empty(c, np.int64),
        np.empty(c, np.int64), np.empty(c, np.int64), np.empty(c, np.int64), np.empty(r, np.int32),
        np.empty((c, 3)), np.empty((r, 3)), np.empty(c), np.empty(c, np.int64), np.empty(c, np.int64),
        np.zeros(1, np.int64), np.zeros(1, np.int64),
    )


@njit(cache=True, no_cfunc_wrapper=True)
def substep_view(cs):
    """A SubstepSetRef as its SubstepSet tuple (the same arrays), for Python: tests and
    diagnostics (the StructRef has no attributes outside compiled code)."""
    return as_tuple(cs, SubstepSet)


@njit(cache=True, no_cfunc_wrapper=True)
def empty_substep_set():
    """A SubstepSet with no room yet, for the first soft_contact_phase (it grows it)."""
    return _make_set(1, 1)


@njit(cache=True, no_cfunc_wrapper=True)
def _resized(a, n):
    out = np.empty((n,) + a.shape[1:], a.dtype)
    m = min(n, a.shape[0])
    flat_out, flat_a = out.reshape(-1), a.reshape(-1)  # both C-contiguous
    for i in range(m * (flat_a.shape[0] // max(a.shape[0], 1))):  # a loop, not out[:m] = a[:m]:
        flat_out[i] = flat_a[i]  # no shape-error code to compile
    return out


@njit(cache=True, no_cfunc_wrapper=True)
def _grow(cs, c, r):
    """cs with room for at least c members and r flat row entries (contents kept)."""
    if c <= cs.gid.shape[0] and r <= cs.nbr.shape[0]:
        return cs
    c = max(c, 2 * cs.gid.shape[0]) if c > cs.gid.shape[0] else cs.gid.shape[0]
    r = max(r, 2 * cs.nbr.shape[0]) if r > cs.nbr.shape[0] else cs.nbr.shape[0]
    return SubstepSetRef(
        cs.n, cs.n_rows, _resized(cs.gid, c), _resized(cs.path, c), _resized(cs.cur, c),
        _resized(cs.dev, c), _resized(cs.ft, c), _resized(cs.dev_max, c), _resized(cs.start, c),
        _resized(cs.active, c), _resized(cs.wake, c), _resized(cs.touched, c), _resized(cs.has_row, c),
        _resized(cs.queue, c), _resized(cs.rs, c), _resized(cs.rc, c), _resized(cs.nbr, r), _resized(cs.shear, r),
        _resized(cs.touch, r), _resized(cs.collisions, c), _resized(cs.max_overlap, c),
        _resized(cs.n_touch, c),
        _resized(cs.contact_substeps, c), _resized(cs.overlap_sum, c), _resized(cs.bed_overlap_max, c),
        _resized(cs.slot_id, c), _resized(cs.slot_c, c), _resized(cs.slot_shear, c), _resized(cs.in_bed, c),
        _resized(cs.last_contact, c), _resized(cs.nrm, c), _resized(cs.impacts, c), _resized(cs.jump_t0, c),
        _resized(cs.jump_x0, c), _resized(cs.jump_ymax, c), _resized(cs.block, c), _resized(cs.jump_n0, c),
        _resized(cs.jump_c0, c), _resized(cs.nn, c), _resized(cs.nx, r), _resized(cs.at, c),
        _resized(cs.image, r), _resized(cs.retry, c), _resized(cs.flagged, c), _resized(cs.go, c), cs.retired,
        cs.widened,
    )


# ----------------------------------------------------------------------------- path
# Everything below works on a SubstepSet (member indices a, b); the grain arrays are read
# and written only when the set is gathered, scattered and (rarely) extended.


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _on_path(path, a, c, s, dt):
    """Member a's free-flight position and velocity along axis c at s (hermite_point of its
    path row: x₀, u₀, ϖ₀, x₁, u₁, ϖ₁)."""
    return hermite_point(path[a, c], path[a, 9 + c], path[a, 3 + c], path[a, 12 + c], s, dt)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _set_path(cs, a, s, dt):
    """cur (P, V, W) of member a at s: free-flight path plus its deviation."""
    path, cur, dev = cs.path, cs.cur, cs.dev
    for c in range(3):
        x, v = _on_path(path, a, c, s, dt)
        cur[a, c] = x + dev[a, c]
        cur[a, 3 + c] = v + dev[a, 3 + c]
        cur[a, 6 + c] = _spin_of(cs, a, s, c)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _set_place(cs, a, s, dt):
    """cur P of member a at s (that of _set_path), for a retired member: its V and W are
    worked out when read (_velocity_of, _spin_of; "Retired members")."""
    for c in range(3):
        cs.cur[a, c] = _on_path(cs.path, a, c, s, dt)[0] + cs.dev[a, c]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _velocity_of(cs, a, s, dt, c):
    """cur V of member a along axis c at s, as _set_path works it out (the same bits)."""
    return _on_path(cs.path, a, c, s, dt)[1] + cs.dev[a, 3 + c]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _spin_of(cs, a, s, c):
    """cur W of member a along axis c at s (spin linear between the step's ends)."""
    p = cs.path
    return (1.0 - s) * p[a, 6 + c] + s * p[a, 15 + c] + cs.dev[a, 6 + c]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _position_of(cs, b, s, dt):
    """x of member b at s (that of _state_of): its current position when active, else its
    point on the free-flight path (the inlined hermite_point's unused velocity is dropped by
    the compiler). The force loop reads it from ``at`` (_at), once per member and sub-step."""
    if cs.active[b] != 0:
        return cs.cur[b, 0], cs.cur[b, 1], cs.cur[b, 2]
    p = cs.path
    return _on_path(p, b, 0, s, dt)[0], _on_path(p, b, 1, s, dt)[0], _on_path(p, b, 2, s, dt)[0]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _state_of(cs, b, s, dt):
    """(x, v, ω) of member b at s: cur when active (a retired one's V and W worked out
    now: _set_place), else its free-flight path."""
    if cs.active[b] == ACTIVE:
        c = cs.cur
        return c[b, 0], c[b, 1], c[b, 2], c[b, 3], c[b, 4], c[b, 5], c[b, 6], c[b, 7], c[b, 8]
    if cs.active[b] != 0:
        c = cs.cur
        return (c[b, 0], c[b, 1], c[b, 2], _velocity_of(cs, b, s, dt, 0), _velocity_of(cs, b, s, dt, 1),
                _velocity_of(cs, b, s, dt, 2), _spin_of(cs, b, s, 0), _spin_of(cs, b, s, 1), _spin_of(cs, b, s, 2))
    p = cs.path
    x0, v0 = _on_path(p, b, 0, s, dt)
    x1, v1 = _on_path(p, b, 1, s, dt)
    x2, v2 = _on_path(p, b, 2, s, dt)
    return (x0, x1, x2, v0, v1, v2,
            (1.0 - s) * p[b, 6] + s * p[b, 15],
            (1.0 - s) * p[b, 7] + s * p[b, 16],
            (1.0 - s) * p[b, 8] + s * p[b, 17])


# ----------------------------------------------------------------------------- forces
# The sub-step kernels allocate nothing and are compiled without reference counting
# (_nrt=False): field reads of the named tuples otherwise cost atomic increments and
# decrements in the innermost loops (flight/spheres.py).


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _grain_force(a, cs, model, s, dt, h, update, blk):
    """Contact force and torque on active member a at sub-step position s (the one law,
    physics/contact_law.spring_dashpot; both grains of a pair compute exactly negated
    vectors, as every input to it flips sign exactly); h: the sub-step the tangential
    spring advances by. The separation from a neighbour is min_image's, with the pair's
    periodic shift of the step (``image``, _set_row) instead of a division per pair and
    axis: the same bits, ~10 % of the sub-steps at 3.94 %. A neighbour in another block
    than ``blk`` is not looked at: it is out of touch for the whole step, which
    _conflicts checks afterwards ("Blocks")."""
    d = model.diameter
    d2 = d * d
    rad = 0.5 * d
    meff = 0.5 * model.mass
    kn, kt, mu = model.kn, model.kt, model.friction
    damp_n = meff * model.gamma_n
    damp_t = meff * model.gamma_t
    at_radius = model.lever == LEVER_RADIUS
    cur, active, nbr, shear, touch, block, at = cs.cur, cs.active, cs.nbr, cs.shear, cs.touch, cs.block, cs.at
    image = cs.image
    fx = 0.0
    fy = 0.0
    fz = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    touching = 0
    osum = 0.0
    omax = cs.max_overlap[a]
    xi, yi, zi = cur[a, 0], cur[a, 1], cur[a, 2]
    r0 = cs.rs[a]
    # the near entries only (the row's first nn): a far one is out of touch all step, and
    # never touching (_near_pairs keeps those near), so looking at it would add nothing
    for k in range(np.uint64(r0), np.uint64(r0 + cs.nn[a])):
        # unsigned indices: Numba wraps a negative signed index round (a test and a conditional
        # move per array read, ~5 % of the sub-steps at 3.94 %); these are never negative
        b = np.uint64(nbr[k])
        rsq = d2
        delx = dely = delz = 0.0
        if block[b] == blk:
            # min_image with the pair's shift of the step (the same bits: cells.image_shift)
            delx = (xi - at[b, 0]) - image[k, 0]
            dely = (yi - at[b, 1]) - image[k, 1]
            delz = (zi - at[b, 2]) - image[k, 2]
            rsq = delx * delx + dely * dely + delz * delz
        if rsq >= d2:
            if touch[k] != 0:
                touch[k] = 0
                shear[k, 0] = 0.0
                shear[k, 1] = 0.0
                shear[k, 2] = 0.0
            continue
        _, _, _, vj0, vj1, vj2, wj0, wj1, wj2 = _state_of(cs, b, s, dt)
        if active[b] != ACTIVE:
            cs.wake[a] = 1  # b is not sub-stepped yet, or retired
        touching += 1
        if touch[k] == 0:
            touch[k] = 1
            cs.collisions[a] += 1
        if rsq == 0.0:
            continue
        r = math.sqrt(rsq)
        rinv = 1.0 / r
        n0, n1, n2 = delx * rinv, dely * rinv, delz * rinv
        arm = rad if at_radius else 0.5 * r
        vr0, vr1, vr2 = sphere_contact_velocity(n0, n1, n2, arm, cur[a, 3] - vj0, cur[a, 4] - vj1, cur[a, 5] - vj2,
                                                cur[a, 6] + wj0, cur[a, 7] + wj1, cur[a, 8] + wj2)
        fn, fs1, fs2, fs3, shear[k, 0], shear[k, 1], shear[k, 2] = spring_dashpot(
            n0, n1, n2, d - r, vr0, vr1, vr2, shear[k, 0], shear[k, 1], shear[k, 2], h, update,
            kn, kt, damp_n, damp_t, mu)
        fx += fn * n0 + fs1
        fy += fn * n1 + fs2
        fz += fn * n2 + fs3
        t0, t1, t2 = lever_torque(n0, n1, n2, arm, fs1, fs2, fs3)  # T = −arm n × F_t
        tx -= t0
        ty -= t1
        tz -= t2
        osum += d - r
        if d - r > omax:
            omax = d - r
    cs.max_overlap[a] = omax
    ft = cs.ft
    ft[a, 0] = fx
    ft[a, 1] = fy
    ft[a, 2] = fz
    ft[a, 3] = tx
    ft[a, 4] = ty
    ft[a, 5] = tz
    cs.n_touch[a] = touching
    if touching > 0:
        cs.touched[a] = 1
        if update:
            cs.contact_substeps[a] += touching
            cs.overlap_sum[a] += osum


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _bed_force(a, cs, st, bc, s, dt, h, update):
    """Soft contact of active member a with the bed spheres it touches at sub-step s, added
    to its force and torque (module docstring, "The bed in the contact phase").
    The law of the grain pairs (physics/contact_law) with a fixed partner: m_eff = m, the bed's
    restitution (γ_n from it) and friction, the same k_n and k_t."""
    cur, slot_id, slot_c = cs.cur, cs.slot_id, cs.slot_c
    px = cur[a, 0]
    py = cur[a, 1]
    pz = cur[a, 2]
    used = 0
    for k in range(BED_SLOTS):
        if slot_id[a, k] != FREE:
            used += 1
    if used == 0 and py >= 0.5:
        if update:
            cs.in_bed[a] = 0
        return
    packed = bc.params[0] != 0.0
    mu = bc.params[2]
    damp_n = bc.params[4]
    kn = bc.params[5]
    kt = bc.params[6]
    slot_shear = cs.slot_shear
    if update and py < 0.5:
        if packed:
            ix, iz = bed_cell(bc, px, pz)
            for sc in range(9):
                c = bed_stencil_cell(bc, ix, iz, sc)
                for q in range(bc.cell_start[c], bc.cell_start[c] + bc.cell_count[c]):
                    kb = bc.order[q]
                    ax, ay, az = bed_offset(bc, kb, px, py, pz)
                    if ax * ax + ay * ay + az * az >= 1.0:
                        continue
                    known = False
                    free = -1
                    for k in range(BED_SLOTS):
                        if slot_id[a, k] == kb:
                            known = True
                        elif slot_id[a, k] == FREE and free < 0:
                            free = k
                    if known or free < 0:
                        continue
                    slot_id[a, free] = kb
                    slot_c[a, free, 0] = px - ax
                    slot_c[a, free, 1] = py - ay
                    slot_c[a, free, 2] = pz - az
                    slot_shear[a, free, 0] = 0.0
                    slot_shear[a, free, 1] = 0.0
                    slot_shear[a, free, 2] = 0.0
                    used += 1
        elif used == 0:
            # virtual bed: a bed grain of diameter d placed where the grain's bottom
            # crossed the bed top, its normal tilted at random (bed.virtual.virtual_bed_normal)
            nrm = cs.nrm[a]
            if cur[a, 4] < 0.0:
                xi1, xi2 = uniform2(bc.ints[0], cs.gid[a], cs.impacts[a])
                virtual_bed_normal(cur[a, 3:6], xi1, xi2, bc.params[3], nrm)
            else:
                nrm[0] = 0.0
                nrm[1] = 1.0
                nrm[2] = 0.0
            depth = 1.0 - (0.5 - py)
            slot_id[a, 0] = VIRTUAL
            slot_c[a, 0, 0] = px - depth * nrm[0]
            slot_c[a, 0, 1] = py - depth * nrm[1]
            slot_c[a, 0, 2] = pz - depth * nrm[2]
            slot_shear[a, 0, 0] = 0.0
            slot_shear[a, 0, 1] = 0.0
            slot_shear[a, 0, 2] = 0.0
            used = 1
    if used == 0:
        if update:
            cs.in_bed[a] = 0
        return
    fx = 0.0
    fy = 0.0
    fz = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    nb = 0
    for k in range(BED_SLOTS):
        if slot_id[a, k] == FREE:
            continue
        delx = px - slot_c[a, k, 0]
        dely = py - slot_c[a, k, 1]
        delz = pz - slot_c[a, k, 2]
        rsq = delx * delx + dely * dely + delz * delz
        if rsq >= 1.0:
            slot_id[a, k] = FREE
            continue
        nb += 1
        if rsq == 0.0:
            continue
        r = math.sqrt(rsq)
        rinv = 1.0 / r
        n0, n1, n2 = delx * rinv, dely * rinv, delz * rinv
        # the bed sphere is fixed (v = 0, ω = 0); contact point midway between equal spheres
        arm = 0.5 * r
        vr0, vr1, vr2 = sphere_contact_velocity(n0, n1, n2, arm, cur[a, 3], cur[a, 4], cur[a, 5],
                                                cur[a, 6], cur[a, 7], cur[a, 8])
        fn, fs1, fs2, fs3, slot_shear[a, k, 0], slot_shear[a, k, 1], slot_shear[a, k, 2] = spring_dashpot(
            n0, n1, n2, 1.0 - r, vr0, vr1, vr2, slot_shear[a, k, 0], slot_shear[a, k, 1], slot_shear[a, k, 2],
            h, update, kn, kt, damp_n, 0.0, mu)
        fx += fn * n0 + fs1
        fy += fn * n1 + fs2
        fz += fn * n2 + fs3
        t0, t1, t2 = lever_torque(n0, n1, n2, arm, fs1, fs2, fs3)
        tx -= t0
        ty -= t1
        tz -= t2
        if 1.0 - r > cs.bed_overlap_max[a]:
            cs.bed_overlap_max[a] = 1.0 - r
    ft = cs.ft
    ft[a, 0] += fx
    ft[a, 1] += fy
    ft[a, 2] += fz
    ft[a, 3] += tx
    ft[a, 4] += ty
    ft[a, 5] += tz
    if nb > 0:
        cs.touched[a] = 1
    if update:
        step = bc.ints[1]
        t_now = bc.t0[0] + s * dt
        if nb > 0:
            if cs.in_bed[a] == 0:
                # a bed contact begins: an impact; it ends a jump if the grain was airborne
                cs.impacts[a] += 1
                if cs.last_contact[a] < step - 1:
                    close_jump(st, cs.gid[a], cs.jump_t0[a], px - cs.jump_x0[a], cs.jump_ymax[a] - 0.5, t_now,
                               bc.params[BC_MIN_JUMP_DURATION], bc.params[BC_MIN_JUMP_HEIGHT])
            # in contact: the next jump starts when it ends
            cs.jump_t0[a] = t_now
            cs.jump_x0[a] = px
            cs.jump_ymax[a] = py
            cs.last_contact[a] = step
        cs.in_bed[a] = 1 if nb > 0 else 0


DRIFT_CHUNKS = 64  # fixed chunks of the drift's min/max reduction (exact in any order)


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _drift(x0w, pos, ref, box, per):
    """The common drift c (2, 3) at x₀ and at x₁: per axis, the middle of the range of the
    grains' displacements from the list's reference positions. Any vector common to all
    grains may be taken out of the list's validity test ("Neighbour list"); the middle of
    the range makes the largest remaining displacement the smallest."""
    n = pos.shape[0]
    lo = np.full((DRIFT_CHUNKS, 2, 3), np.inf)
    hi = np.full((DRIFT_CHUNKS, 2, 3), -np.inf)
    size = (n + DRIFT_CHUNKS - 1) // DRIFT_CHUNKS
    for q in prange(DRIFT_CHUNKS):
        for i in range(q * size, min(n, (q + 1) * size)):
            for a in range(3):
                e0 = min_image(x0w[i, a] - ref[i, a], box[a], per[a])
                e1 = min_image(pos[i, a] - ref[i, a], box[a], per[a])
                lo[q, 0, a] = min(lo[q, 0, a], e0)
                hi[q, 0, a] = max(hi[q, 0, a], e0)
                lo[q, 1, a] = min(lo[q, 1, a], e1)
                hi[q, 1, a] = max(hi[q, 1, a], e1)
    c = np.zeros((2, 3))
    if n == 0:
        return c
    for k in range(2):
        for a in range(3):
            low = np.inf
            high = -np.inf
            for q in range(DRIFT_CHUNKS):
                low = min(low, lo[q, k, a])
                high = max(high, hi[q, k, a])
            c[k, a] = 0.5 * (low + high)
    return c


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _reach(x0w, pos, vel, dt, cl, ph, c):
    """D (reach of the free-flight path from x₀) per grain; returns the largest
    displacement bound from the list's reference positions, less the common drift c
    (_drift): ``max(|x₀ − x_ref − c₀|, |x₁ − x_ref − c₁|) + b`` ("Neighbour list")."""
    n = pos.shape[0]
    box, per, ref = cl.grid.box, cl.grid.periodic, cl.ref_pos
    # arrays unpacked before the parallel loop: Numba 0.68 drops writes made in a prange
    # body through a named tuple's arrays (flight/spheres.py)
    active, reach, worst = ph.active, ph.reach, ph.ref_bound
    for i in prange(n):
        active[i] = 0
        ch = 0.0
        b0 = 0.0
        b1 = 0.0
        r0 = 0.0
        r1 = 0.0
        for a in range(3):
            step = pos[i, a] - x0w[i, a]
            vbar = step / dt
            ch += step * step
            b0 += (x0w[i, 3 + a] - vbar) ** 2
            b1 += (vel[i, a] - vbar) ** 2
            e0 = min_image(x0w[i, a] - ref[i, a], box[a], per[a]) - c[0, a]
            e1 = min_image(pos[i, a] - ref[i, a], box[a], per[a]) - c[1, a]
            r0 += e0 * e0
            r1 += e1 * e1
        bulge = 0.25 * dt * (math.sqrt(b0) + math.sqrt(b1))
        reach[i] = math.sqrt(ch) + bulge
        worst[i] = math.sqrt(max(r0, r1)) + bulge
    return worst.max() if n > 0 else 0.0  # the reduction reads the filled array



@njit(cache=True, no_cfunc_wrapper=True)
def _engage(x0w, pos, vel, dt, model, cl, ph, bc, c0):
    """start[i]: when grain i joins the sub-steps; active[i] = 0. A grain that ends the
    step below the bed top will be moved by its (hard) bed rebound by up to twice its
    reach: that margin is added to the test that makes it a candidate (_may_meet).
    c0: the drift taken out of the list's validity test at x₀ (_drift)."""
    d = model.diameter
    box, per = cl.grid.box, cl.grid.periodic
    _margins(x0w, pos, ph.reach, ph.margin)
    _engage_listed(x0w, pos, box, per, cl.nbr, cl.nbr_count, cl.n_touch, bc.in_bed, bc.slot_id, ph.margin, d,
                   ph.active, ph.start, cl.order)
    _engage_unlisted(x0w, pos, d, cl, ph, c0)
    _engage_start(x0w, pos, vel, dt, box, per, cl.nbr, cl.nbr_count, cl.n_touch, bc.in_bed, bc.slot_id, ph.reach, d,
                  ph.start, cl.order, bc.last_contact, bc.ints[1], bc.params[0] != 0.0)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _first_bed(x0w, pos, vel, dt, i):
    """Lower bound on the step fraction s at which grain i's bottom can first go below the
    bed top (y < 1/2; inf: not in this step), by the bound of _chord on its cubic."""
    return _bed_time(x0w[i, 1], pos[i, 1], x0w[i, 4], vel[i, 1], dt)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _bed_time(y0, y1, u0, u1, dt):
    """_first_bed of a cubic Hermite (y0, u0) → (y1, u1) over dt: the fraction of dt before
    which its height stays above 1/2 (inf: all along)."""
    vbar = (y1 - y0) / dt
    low = y0 - 0.5 * (1.0 + TOUCH_EPS) - (4.0 / 27.0) * dt * (abs(u0 - vbar) + abs(u1 - vbar))
    if low <= 0.0:
        return 0.0
    if y1 >= y0:
        return np.inf
    return low / (y0 - y1) * (1.0 - TOUCH_EPS)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _may_meet(x0w, pos, margin, i, j, d, box, per):
    """Whether grains i and j may come within d in this step, counting the bed-rebound
    margins: by the coarse bound |r(s)| ≥ |r₀| − s|Δx_i − Δx_j| − (b_i + b_j) on the
    undeflected paths (Δx the step's chord, b = margin − |Δx| the bulge of the cubic off it
    plus the rebound margin), i.e. when |r₀| − d − b_i − b_j ≤ |Δx_i − Δx_j|. Only pairs
    with |r₀| < d + margin_i + margin_j can. The same bits whichever grain of the pair
    asks (worked out from the lower id), so the answer does not depend on which of the
    two found the pair (_engage_listed, _engage_unlisted)."""
    a = min(i, j)
    b = max(i, j)
    dx = min_image(x0w[a, 0] - x0w[b, 0], box[0], per[0])
    dy = min_image(x0w[a, 1] - x0w[b, 1], box[1], per[1])
    dz = min_image(x0w[a, 2] - x0w[b, 2], box[2], per[2])
    lim = d + margin[a] + margin[b]
    r2 = dx * dx + dy * dy + dz * dz
    if r2 >= lim * lim:
        return False
    cxa = pos[a, 0] - x0w[a, 0]
    cya = pos[a, 1] - x0w[a, 1]
    cza = pos[a, 2] - x0w[a, 2]
    cxb = pos[b, 0] - x0w[b, 0]
    cyb = pos[b, 1] - x0w[b, 1]
    czb = pos[b, 2] - x0w[b, 2]
    ba = margin[a] - math.sqrt(cxa * cxa + cya * cya + cza * cza)
    bb = margin[b] - math.sqrt(cxb * cxb + cyb * cyb + czb * czb)
    gap = math.sqrt(r2) - d - ba - bb
    if gap <= 0.0:
        return True
    return gap <= math.sqrt((cxa - cxb) ** 2 + (cya - cyb) ** 2 + (cza - czb) ** 2)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _touching_now(i, n_touch, in_bed, slot_id):
    """In contact with a grain or the bed at the last force evaluation."""
    if n_touch[i] > 0 or in_bed[i] != 0:
        return True
    for slot in range(slot_id.shape[1]):
        if slot_id[i, slot] != FREE:
            return True
    return False


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _engage_listed(x0w, pos, box, per, nbr, nbr_count, n_touch, in_bed, slot_id, margin, d, active, start, order):
    """First pass of the candidate test: start[i] = 0 when grain i is in contact now or
    may meet a list neighbour (_may_meet), else inf; active[i] = 0.

    Every pair that may meet is in the list when both grains are within half the skin
    of the list's reach (_engage_unlisted takes the others), so which grains are
    candidates does not depend on when the list was built or with what skin."""
    # every array an argument: Numba 0.68 dropped this loop's writes when they went to an
    # array taken from a named tuple inside the function. Grains in the list's cell order:
    # neighbouring grains' rows are then read from cache, not from all over memory.
    for q in prange(x0w.shape[0]):
        i = order[q]
        active[i] = 0
        hit = _touching_now(i, n_touch, in_bed, slot_id)
        k = 0
        m = nbr_count[i]
        while not hit and k < m:
            hit = _may_meet(x0w, pos, margin, i, nbr[i, k], d, box, per)
            k += 1
        start[i] = 0.0 if hit else np.inf


@njit(cache=True, no_cfunc_wrapper=True)
def _engage_unlisted(x0w, pos, d, cl, ph, c0):
    """Second pass of the candidate test: the pairs the list need not hold.

    The list holds every pair within the cutoff d + s of each other at the reference
    positions. A pair that may meet is within d + m_i + m_j at x₀ (m the margin), so
    within d + u_i + u_j at the references, u = |x₀ − x_ref − c₀| + m (c₀ any
    displacement common to all grains: the drift of "Neighbour list"); it is listed whenever
    u_i and u_j are both at most s/2. Each grain with a larger u (typically one hitting
    the bed fast: m is three reaches) is tested here against every grain within
    d + u_i + max u of its reference position, found through the list's cells (built at
    the references), and a pair that may meet makes both candidates. Serial: such grains
    are few."""
    n = x0w.shape[0]
    g = cl.grid
    box, per, ref, margin, start = g.box, g.periodic, cl.ref_pos, ph.margin, ph.start
    half = 0.5 * (cl.cutoff - d) - TOUCH_EPS * d
    wide = np.empty(n, np.int64)
    wide_u = np.empty(n)
    n_wide = 0
    u_max = 0.0
    for i in range(n):
        e2 = 0.0
        for a in range(3):
            e = min_image(x0w[i, a] - ref[i, a], box[a], per[a]) - c0[a]
            e2 += e * e
        u = math.sqrt(e2) + margin[i]
        u_max = max(u_max, u)
        if u > half:
            wide[n_wide] = i
            wide_u[n_wide] = u
            n_wide += 1
    ny, nz = g.n[1], g.n[2]
    for t in range(n_wide):
        i = wide[t]
        reach = (d + wide_u[t] + u_max) * (1.0 + TOUCH_EPS)
        c = cl.cell_of[i]
        fx, mx = axis_span(c // (ny * nz), g.n[0], per[0], int(math.ceil(reach / g.size[0])))
        fy, my = axis_span((c // nz) % ny, ny, per[1], int(math.ceil(reach / g.size[1])))
        fz, mz = axis_span(c % nz, nz, per[2], int(math.ceil(reach / g.size[2])))
        for sx in range(mx):
            cx = (fx + sx) % g.n[0]
            for sy in range(my):
                cy = (fy + sy) % ny
                for sz in range(mz):
                    cell = (cx * ny + cy) * nz + (fz + sz) % nz
                    for q in range(cl.cell_start[cell], cl.cell_start[cell] + cl.cell_count[cell]):
                        j = cl.order[q]
                        if j != i and _may_meet(x0w, pos, margin, i, j, d, box, per):
                            start[i] = 0.0
                            start[j] = 0.0


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _engage_start(x0w, pos, vel, dt, box, per, nbr, nbr_count, n_touch, in_bed, slot_id, reach, d, start, order,
                  last_contact, step, packed):
    """Which grains are sub-stepped in this step, and from when: start[i] (step fraction
    s; inf: not at all), from the candidates the first two passes marked (start[i] = 0).

    A grain is sub-stepped when it is a *candidate* (it may meet another grain, counting
    the bed-rebound margins, _may_meet; or is in contact with a grain or the bed now) or
    rests on the packed bed. This decides which grains have soft bed contacts (the
    others the hard bed of phase 3). A grain in contact now starts at 0; any other starts
    at the earliest time it can touch a grain or the bed by the tight bound of
    _first_touch / _first_bed (the chord's direction, not only its length: in the dense
    layer most neighbours within reach move alongside or apart). Until then nothing acts
    on it, so joining later gives the same bits as joining at the coarse bound (the
    deviation is exactly zero until the first contact), and a grain that no bound lets
    touch anything in the step is not sub-stepped at all: its free flight and the hard
    bed are the same (its path stays above the bed top). The list holds every pair that
    can come within d, so the tight bound needs only its rows. The cost: module
    docstring, "Which grains are sub-stepped"."""
    for q in prange(x0w.shape[0]):
        i = order[q]
        # a grain resting or rolling on the packed bed (bed contact in the last step) whose
        # path reaches the bed again keeps its soft bed contacts: the hard rebound and
        # push-out would make it bounce in its hollow at ~g'Δt each step (issue 20)
        lasting = False
        if packed and last_contact[i] >= step - 1:
            cxi = pos[i, 0] - x0w[i, 0]
            cyi = pos[i, 1] - x0w[i, 1]
            czi = pos[i, 2] - x0w[i, 2]
            bulge = reach[i] - math.sqrt(cxi * cxi + cyi * cyi + czi * czi)
            lasting = min(x0w[i, 1], pos[i, 1]) - bulge < 0.5
        if start[i] > 1.0 and not lasting:
            continue  # touches no grain in this step: free flight and the hard bed
        if _touching_now(i, n_touch, in_bed, slot_id):
            start[i] = 0.0
            continue
        tight = _first_bed(x0w, pos, vel, dt, i)
        for k in range(nbr_count[i]):
            if tight <= 0.0:
                break
            j = nbr[i, k]
            tight = min(tight, _first_touch(x0w[i, 0:3], pos[i], x0w[i, 3:6], vel[i], x0w[j, 0:3], pos[j],
                                            x0w[j, 3:6], vel[j], box, per, dt, d))
        start[i] = tight


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _margins(x0w, pos, reach, margin):
    # the hard bed pass moves a grain only when it ends the step with its bottom below the
    # bed top (y < 1/2), by at most twice its reach (flight.spheres._bed_impact)
    for i in prange(x0w.shape[0]):
        margin[i] = reach[i] + (2.0 * reach[i] if pos[i, 1] < 0.5 else 0.0)



@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _block_member(t, lo, hi, app):
    """The t-th member of a block: lo..hi-1 from the gather, then app.. (appended while it ran)."""
    return lo + t if lo + t < hi else app + (lo + t - hi)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _block_size(cs, lo, hi, app):
    """Members of a block: lo..hi-1 and those appended from app (_block_member)."""
    return hi - lo + cs.n[0] - app


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _forces(cs, st, bc, model, s, dt, h, lo, hi, app, blk, t0, t1, backoff, listed):
    """Forces on the active members t0..t1-1 of block blk (_block_member; ``listed``: those
    of cs.go, the active ones _kick_drift listed) at s; returns
    how many touched a member that was not active (to be woken). At s = 0 (the set-up)
    the tangential springs and contact records are not advanced: they hold the previous
    step's last sub-step. (``update`` is a run-time value, not a compile-time one: one
    compiled copy of the force code serves both.) Each member's force is its own sum over
    its own row (both grains of a pair compute it): members can be done in any order.
    The members that touched one not active are listed in cs.flagged[t0:], in this order.
    ``backoff`` > 0: then a member that touches nothing retires until it may touch
    something unforced (_quiet_until, which needs the members one after another: which
    ones retire depends on their order, the result does not), or tries again ``backoff``
    sub-steps on.
    Returns how many were woken and the sub-steps the retired members have left."""
    update = s > 0.0
    woke = 0
    left = 0
    active = cs.active
    for t in range(t0, t1):
        # the same members, in the same order; unsigned: no wraparound of negative indices (_grain_force)
        a = np.uint64(cs.go[t] if listed else _block_member(t, lo, hi, app))
        if active[a] != ACTIVE:
            continue
        _grain_force(a, cs, model, s, dt, h, update, blk)
        _bed_force(a, cs, st, bc, s, dt, h, update)
        if cs.wake[a] != 0:
            cs.flagged[t0 + woke] = a  # for _wake_up; each range t0..t1-1 writes its own part
            woke += 1
        if backoff > 0.0 and update and s < 1.0 and s >= cs.retry[a] and cs.n_touch[a] == 0:
            until = _quiet_until(cs, a, s, dt, h, model.diameter, blk)
            if until > s:
                active[a] = RETIRED
                cs.retry[a] = until  # forced again from the first sub-step at or after it
                left += _substeps_left(s, dt, h)
            else:
                cs.retry[a] = _next_try(s, dt, h, backoff)
    return woke, left


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _substeps_left(s, dt, h):
    """Sub-steps of the step after s: a retired member's count (RETIRED_SUBSTEPS), added
    when it retires at s and taken back when it is forced again at s (_force_again)."""
    return round((1.0 - s) * dt / h)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _next_try(s, dt, h, backoff):
    """When a member forced at s that may not retire (or has just been forced again)
    tries to retire again: ``backoff`` sub-steps on (a step fraction)."""
    return s + backoff * h / dt


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _force_again(cs, a, s, dt, h, backoff):
    """Retired member a is forced (ACTIVE) again from s: its quiet time is over
    (_kick_drift) or an active one touched it (_wake_up). Its deviation went on unforced,
    as when forced by nothing; it may try to retire again ``backoff`` sub-steps on. Its
    cur is made whole again (retired, only its position was kept: _set_place)."""
    cs.active[a] = ACTIVE
    _set_path(cs, a, s, dt)
    cs.retry[a] = _next_try(s, dt, h, backoff)
    cs.retired[0] -= _substeps_left(s, dt, h)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _rest_of_path(cs, b, s, dt, c):
    """Member b's course along axis c over the rest of the step, s → 1, as a cubic Hermite
    (x, u) → (x₁, u₁) over (1 − s)Δt: an inactive member's free-flight path; an active one
    forced by nothing from s on moves on its path plus a deviation of constant velocity
    δu, which adds δx + δu(σ − s)Δt to the cubic: another cubic through the shifted ends."""
    p = cs.path
    if cs.active[b] == 0:
        x, u = _on_path(p, b, c, s, dt)
        return x, u, p[b, 9 + c], p[b, 12 + c]
    du = cs.dev[b, 3 + c]
    u = cs.cur[b, 3 + c] if cs.active[b] == ACTIVE else _velocity_of(cs, b, s, dt, c)  # retired: _set_place
    return cs.cur[b, c], u, p[b, 9 + c] + cs.dev[b, c] + du * ((1.0 - s) * dt), p[b, 12 + c] + du


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _quiet_until(cs, a, s, dt, h, d, blk):
    """The step fraction up to which active member a, touching nothing at s, is sure to
    touch nothing if nothing forces it ("Retired members"; 0: not even QUIET_MIN
    sub-steps on; > 1: the whole step): before its course can reach the bed top (_bed_time)
    or come within d of the course of a near partner of its block that is not active
    (inactive or retired; _chord_touch). An active partner looks at the pair at every
    sub-step and wakes a if they touch; one that comes later in _forces' order and
    retires at s too sees a retired, so that pair is checked once. (So the members must
    be done one after another: _forces retires none when its members are cut between
    threads.)"""
    for c in range(6):
        if cs.ft[a, c] != 0.0:
            return 0.0
    for k in range(BED_SLOTS):
        if cs.slot_id[a, k] != FREE:
            return 0.0
    span = (1.0 - s) * dt
    # a grain whose centre is at or above 0.5 touches no bed sphere (_bed_force)
    y, v, y1, v1 = _rest_of_path(cs, a, s, dt, 1)
    first = _bed_time(y, y1, v, v1, span)  # fractions of the rest of the step, s → 1
    least = QUIET_MIN * h / span
    if first <= least:
        return 0.0
    active, nbr, block, image = cs.active, cs.nbr, cs.block, cs.image
    r0 = cs.rs[a]
    for k in range(np.uint64(r0), np.uint64(r0 + cs.nn[a])):
        b = np.uint64(nbr[k])  # unsigned: no wraparound (_grain_force)
        if block[b] != blk or active[b] == ACTIVE:
            continue  # out of touch all step (_conflicts), or looks at a
        r2 = rd = dd = w0 = w1 = 0.0
        for c in range(3):  # _chord of the two courses
            xa, ua, xa1, ua1 = _rest_of_path(cs, a, s, dt, c)
            xb, ub, xb1, ub1 = _rest_of_path(cs, b, s, dt, c)
            r2, rd, dd, w0, w1 = _chord_add(r2, rd, dd, w0, w1, (xa - xb) - image[k, c], (xa1 - xa) - (xb1 - xb),
                                            ua - ub, ua1 - ub1, span)
        first = min(first, _chord_touch(r2, rd, dd, _bulge(w0, w1), d))
        if first <= least:
            return 0.0
    return s + first * (1.0 - s)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _half_kick(dev, ft, a, h, inv_m, inv_i):
    """Half kick of member a's deviation velocity and spin by its contact force and torque."""
    for c in range(3):
        dev[a, 3 + c] += 0.5 * h * ft[a, c] * inv_m
        dev[a, 6 + c] += 0.5 * h * ft[a, 3 + c] * inv_i


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _kick_drift(cs, model, s_next, dt, h, lo, hi, app, t0, t1, kick_first, listing, backoff, wide2):
    """First half of a sub-step for the active members t0..t1-1 of a block: half kick,
    drift (in member order: sequential memory); the others' position ``at``. The forces at
    s_next follow (_forces), once every member has drifted. ``kick_first``: the previous
    sub-step's second half kick first, in the same pass (the operations of _kick, in its
    order; a member that joined since has zero force, so that kick adds exactly zero).
    ``listing``: also list the members forced at s_next (ACTIVE) in cs.go, in member
    order, for _forces ("Lists instead of scans"); returns how many (else 0). A retired
    member whose quiet time ends by s_next is forced again (it may try to retire again
    ``backoff`` sub-steps on). A member whose |δx|² reaches ``wide2`` (the near filter's
    slack; inf: never) has its and its partners' rows widened (_widen) and is forced at
    s_next, retired or not; in a lane (not ``listing``: rows are shared between lanes) it
    is listed in cs.go from place t0 instead, widened by _substep_part once every lane has
    drifted (nothing reads a row before the forces), and the count returned."""
    inv_m = 1.0 / model.mass
    inv_i = 1.0 / model.inertia
    active, dev, ft, dev_max, go = cs.active, cs.dev, cs.ft, cs.dev_max, cs.go
    n_go = 0
    for t in range(t0, t1):
        a = np.uint64(_block_member(t, lo, hi, app))  # unsigned: no wraparound (_grain_force)
        if active[a] == 0:
            _at(cs, a, s_next, dt)
            continue
        if active[a] == ACTIVE:  # a retired member's force is +0: its kicks would add exactly nothing
            if kick_first:
                _half_kick(dev, ft, a, h, inv_m, inv_i)
            _half_kick(dev, ft, a, h, inv_m, inv_i)
        for c in range(3):
            dev[a, c] += h * dev[a, 3 + c]
        dd = dev[a, 0] ** 2 + dev[a, 1] ** 2 + dev[a, 2] ** 2
        if dd > dev_max[a]:
            if dev_max[a] < wide2 and dd >= wide2:
                if listing:
                    _widen(cs, np.int64(a))  # the lanes' type: one compiled copy
                    if active[a] == RETIRED:
                        cs.retry[a] = s_next  # forced now: its quiet time did not look at its far partners
                else:
                    go[t0 + n_go] = a  # a lane (none retires there): widened after the pass
                    n_go += 1
            dev_max[a] = dd
        if listing and active[a] == RETIRED and s_next >= cs.retry[a]:
            _force_again(cs, a, s_next, dt, h, backoff)  # its quiet time (_quiet_until) is over
        elif active[a] == ACTIVE:
            _set_path(cs, a, s_next, dt)
        else:
            _set_place(cs, a, s_next, dt)  # retired: its V and W are worked out when read
        _at(cs, a, s_next, dt)
        if listing:
            go[n_go] = a
            n_go += active[a] == ACTIVE
    return n_go


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _at(cs, a, s, dt):
    """at[a] = member a's position at s (_position_of), computed once per member and
    sub-step: the force loop reads it for every near pair instead of evaluating the
    partner's path there."""
    x, y, z = _position_of(cs, a, s, dt)
    cs.at[a, 0] = x
    cs.at[a, 1] = y
    cs.at[a, 2] = z


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _positions(cs, s, dt, lo, hi, app, t0, t1):
    """at of the members t0..t1-1 of a block at s (_at)."""
    for t in range(t0, t1):
        _at(cs, _block_member(t, lo, hi, app), s, dt)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _kick(cs, model, h, lo, hi, app, t0, t1):
    """Second half kick of a sub-step (the block's members t0..t1-1)."""
    inv_m = 1.0 / model.mass
    inv_i = 1.0 / model.inertia
    active, dev, ft = cs.active, cs.dev, cs.ft
    for t in range(t0, t1):
        a = _block_member(t, lo, hi, app)
        if active[a] != ACTIVE:  # retired: its force is +0 (_kick_drift)
            continue
        _half_kick(dev, ft, a, h, inv_m, inv_i)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _activate(cs, a, s, dt):
    """Member a joins the sub-steps at s: zero deviation and force, on its free-flight path."""
    for c in range(9):
        cs.dev[a, c] = 0.0
    for c in range(6):
        cs.ft[a, c] = 0.0
    cs.dev_max[a] = 0.0
    _set_path(cs, a, s, dt)
    cs.active[a] = ACTIVE
    cs.retry[a] = 0.0


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _join(cs, cand, ptr, end, before, s_now, dt):
    """Activate the candidates cand[ptr:end] (member indices by start) with start <
    ``before`` (start ≤ 0 when ``before`` is 0) at step fraction s_now. Returns the new
    pointer and how many were activated."""
    joined = 0
    while ptr < end:
        a = cand[ptr]
        t = cs.start[a]
        if not (t < before or (before == 0.0 and t <= 0.0)):
            break
        ptr += 1
        if cs.active[a] == 0:  # else woken earlier
            _activate(cs, a, s_now, dt)
            joined += 1
    return ptr, joined


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _set_member(cs, a, g, x0w, pos, vel, spin, start, blk):
    """Member a is grain g of block blk: its free-flight path, nothing else yet."""
    cs.gid[a] = g
    for c in range(3):
        cs.path[a, c] = x0w[g, c]
        cs.path[a, 3 + c] = x0w[g, 3 + c]
        cs.path[a, 6 + c] = x0w[g, 6 + c]
        cs.path[a, 9 + c] = pos[g, c]
        cs.path[a, 12 + c] = vel[g, c]
        cs.path[a, 15 + c] = spin[g, c]
    cs.start[a] = start[g]
    cs.active[a] = 0
    cs.wake[a] = 0
    cs.touched[a] = 0
    cs.has_row[a] = 0
    cs.rs[a] = 0
    cs.rc[a] = 0
    cs.block[a] = blk


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _set_row(cs, a, st, cl, bc, ph):
    """Member a's neighbour row (all its neighbours must be members, their paths set),
    each pair's periodic shift for the step (``image``: from the separation at x₀; it stays
    min_image's while the pair is closer than half the box, so for every pair that can
    touch), contact history and the state the sub-steps may change, copied in (room must
    exist)."""
    g = cs.gid[a]
    r0 = cs.n_rows[0]
    m = cl.nbr_count[g]
    cs.rs[a] = r0
    cs.rc[a] = m
    cs.nn[a] = m
    box, per = cl.grid.box, cl.grid.periodic
    for k in range(m):
        b = ph.loc[cl.nbr[g, k]]
        cs.nbr[r0 + k] = b
        for c in range(3):
            cs.image[r0 + k, c] = image_shift(cs.path[a, c] - cs.path[b, c], box[c], per[c])
        cs.nx[r0 + k] = r0 + k
        cs.touch[r0 + k] = cl.touch[g, k]
        for c in range(3):
            cs.shear[r0 + k, c] = cl.shear[g, k, c]
    cs.n_rows[0] = r0 + m
    cs.has_row[a] = 1
    cs.collisions[a] = cl.collisions[g]
    cs.max_overlap[a] = cl.max_overlap[g]
    cs.n_touch[a] = cl.n_touch[g]
    cs.contact_substeps[a] = ph.contact_substeps[g]
    cs.overlap_sum[a] = ph.overlap_sum[g]
    cs.bed_overlap_max[a] = ph.bed_overlap_max[g]
    for k in range(BED_SLOTS):
        cs.slot_id[a, k] = bc.slot_id[g, k]
        for c in range(3):
            cs.slot_c[a, k, c] = bc.slot_c[g, k, c]
            cs.slot_shear[a, k, c] = bc.slot_shear[g, k, c]
    cs.in_bed[a] = bc.in_bed[g]
    cs.last_contact[a] = bc.last_contact[g]
    cs.impacts[a] = st.impacts[g]
    cs.jump_t0[a] = st.jump_t0[g]
    cs.jump_x0[a] = st.jump_x0[g]
    cs.jump_ymax[a] = st.jump_ymax[g]
    cs.jump_n0[a] = st.jump_buf_n[g]
    cs.jump_c0[a] = st.jump_count[g]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _chord(x0i, x1i, u0i, u1i, x0j, x1j, u0j, u1j, box, per, dt):
    """Two grains' free-flight paths over the step (x0, u0 → x1, u1) as a chord plus a
    bulge. The Hermite path is H(s) = x₀ + sΔx + Δt[h₁₀(s)(u₀ − ū) + h₁₁(s)(u₁ − ū)] with
    ū = Δx/Δt and |h₁₀|, |h₁₁| ≤ 4/27 on [0, 1], so for the pair r(s) = H_i − H_j:
    |r(s) − (r₀ + sΔ)| ≤ B = (4/27)Δt(|w₀| + |w₁|), Δ = Δx_i − Δx_j, w = the relative
    velocity less Δ/Δt. Returns |r₀|², r₀·Δ, |Δ|², B."""
    r2 = rd = dd = w0 = w1 = 0.0
    for c in range(3):
        r2, rd, dd, w0, w1 = _chord_add(r2, rd, dd, w0, w1, min_image(x0i[c] - x0j[c], box[c], per[c]),
                                        (x1i[c] - x0i[c]) - (x1j[c] - x0j[c]), u0i[c] - u0j[c], u1i[c] - u1j[c], dt)
    return r2, rd, dd, _bulge(w0, w1)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _chord_add(r2, rd, dd, w0, w1, e, dl, du0, du1, dt):
    """_chord's sums with one axis added: e of r₀, dl of Δ, du0 and du1 of the relative
    velocity at the two ends; w0, w1: of |w|Δt, without a division (_bulge)."""
    return r2 + e * e, rd + e * dl, dd + dl * dl, w0 + (du0 * dt - dl) ** 2, w1 + (du1 * dt - dl) ** 2


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _bulge(w0, w1):
    """_chord's bound B = (4/27)Δt(|w₀| + |w₁|) from the squares of |w₀|Δt, |w₁|Δt."""
    return (4.0 / 27.0) * (math.sqrt(w0) + math.sqrt(w1))


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _path_gap(x0i, x1i, u0i, u1i, x0j, x1j, u0j, u1j, box, per, dt):
    """Lower bound on the distance between the free-flight paths of two grains over the
    step: the chord's closest approach less the bulge bound (_chord), less TOUCH_EPS (d)
    for rounding."""
    r2, rd, dd, bulge = _chord(x0i, x1i, u0i, u1i, x0j, x1j, u0j, u1j, box, per, dt)
    return _chord_gap(r2, rd, dd, bulge)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _chord_gap(r2, rd, dd, bulge):
    """The closest approach of a chord r₀ + sΔ, s ∈ [0, 1] (_chord's terms), less the
    bulge and TOUCH_EPS (d)."""
    closest = r2
    if rd < 0.0:
        s = min(1.0, -rd / dd)
        closest = max(0.0, r2 + s * (2.0 * rd + s * dd))
    return math.sqrt(closest) - bulge - TOUCH_EPS


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _first_touch(x0i, x1i, u0i, u1i, x0j, x1j, u0j, u1j, box, per, dt, d):
    """Lower bound on the step fraction s at which two grains' free-flight paths can first
    come within d (inf: not in this step): the chord r₀ + sΔ first within d + B (_chord),
    the smaller root of a quadratic."""
    r2, rd, dd, bulge = _chord(x0i, x1i, u0i, u1i, x0j, x1j, u0j, u1j, box, per, dt)
    return _chord_touch(r2, rd, dd, bulge, d)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _chord_touch(r2, rd, dd, bulge, d):
    """Lower bound on the fraction of the span at which a chord r₀ + sΔ with bulge B
    (_chord's terms) can first come within d (inf: not in the span): the chord first
    within d + B, the smaller root of a quadratic."""
    lim = d * (1.0 + TOUCH_EPS) + bulge
    c0 = r2 - lim * lim
    disc = rd * rd - dd * c0
    # the chord reaches d + B when it closes in (rd < 0) and the quadratic has roots; the
    # smaller root, cancellation-free, is worked out whatever the case and then chosen
    # (selects, not branches: in the dense layer which case holds is a coin toss per pair).
    # Where it is not chosen it divides by 1: inlined, this takes the caller's error model,
    # which may raise on a division by zero (rd = Δ = 0: two grains with the same chord)
    meets = (rd < 0.0) & (disc >= 0.0)
    den = math.sqrt(max(disc, 0.0)) - rd
    root = c0 / (den if meets else 1.0) * (1.0 - TOUCH_EPS)
    later = root if meets else np.inf
    return 0.0 if c0 <= 0.0 else later


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _member_gap(path, a, b, box, per, dt):
    """_path_gap of members a and b of a SubstepSet (``path``: its free-flight rows)."""
    return _path_gap(path[a, 0:3], path[a, 9:12], path[a, 3:6], path[a, 12:15], path[b, 0:3], path[b, 9:12],
                     path[b, 3:6], path[b, 12:15], box, per, dt)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _root(parent, p):
    while parent[p] != p:
        parent[p] = parent[parent[p]]
        p = parent[p]
    return p


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _join_groups(parent, p, q):
    """Union of p's and q's groups in the forest ``parent``; the root stays the least index."""
    rp = _root(parent, p)
    rq = _root(parent, q)
    if rp < rq:
        parent[rq] = rp
    elif rq < rp:
        parent[rp] = rq


@njit(cache=True, no_cfunc_wrapper=True)
def _group_pairs(x0w, pos, vel, cl, ph, gid, dt, forced, limits, tight):
    """Union–find over the members gid[0..m-1] (ph.loc[g]: their index): every member's
    list pairs with other members that come closer than d + 2σ on their free-flight paths
    (or touch now) are joined, starting from the forest ``forced`` (empty: none). ``limits``:
    d + 2σ for pairs with a candidate, for other pairs, and the same two for members with
    ``tight[p]`` set (empty: none). Returns each member's group root (its least member)."""
    m = gid.shape[0]
    box, per = cl.grid.box, cl.grid.periodic
    nbr, nbr_count, touch = cl.nbr, cl.nbr_count, cl.touch
    parent = np.arange(m)
    if forced.shape[0] == m:
        for p in range(m):
            parent[p] = _root(forced, p)  # roots are the least index there too
    use_tight = tight.shape[0] == m
    for p in range(m):
        # every member's list pairs with other members: a neighbour that is woken gets its
        # row, and its pairs are looked at, only later
        i = gid[p]
        t = 2 if use_tight and tight[p] != 0 else 0
        for k in range(nbr_count[i]):
            j = nbr[i, k]
            q = ph.loc[j]
            if q < 0 or _root(parent, p) == _root(parent, q):
                continue  # not a member, or already in p's group (the gap would change nothing)
            lim = limits[t] if ph.start[i] <= 1.0 or ph.start[j] <= 1.0 else limits[t + 1]
            if touch[i, k] == 0 and _path_gap(x0w[i, 0:3], pos[i], x0w[i, 3:6], vel[i], x0w[j, 0:3], pos[j],
                                              x0w[j, 3:6], vel[j], box, per, dt) >= lim:
                continue
            _join_groups(parent, p, q)
    for p in range(m):
        parent[p] = _root(parent, p)
    return parent


@njit(cache=True, no_cfunc_wrapper=True)
def _blocks(x0w, pos, vel, cl, ph, gid, dt, d, cap, forced):
    """Blocks of the members gid[0..m-1] (a grain id each, in cell order; ph.loc[g] their
    index): groups that stay out of touch with each other on paths deviating by less than
    σ from free flight are the connected components of the pairs that come closer than
    d + 2σ (or touch now), joined further by the union–find forest ``forced`` over the
    members (pairs that met across blocks in an earlier pass; empty: none). A group larger
    than ``ph.block_slack[4]`` members (a dense layer percolating) is cut again with the
    tighter slacks ``ph.block_slack[2:4]``. Consecutive groups fill a block up to ``cap``
    members. Returns each member's new index, its block, and the blocks' first members
    (n_blocks + 1)."""
    m = gid.shape[0]
    sl = ph.block_slack
    limits = np.array([d * (1.0 + 2.0 * sl[0]), d * (1.0 + 2.0 * sl[1]), d * (1.0 + 2.0 * sl[2]),
                       d * (1.0 + 2.0 * sl[3])])
    parent = _group_pairs(x0w, pos, vel, cl, ph, gid, dt, forced, limits, np.empty(0, np.uint8))
    size = np.zeros(m, np.int64)
    for p in range(m):
        size[parent[p]] += 1
    giant = np.zeros(m, np.uint8)
    n_giant = 0
    for p in range(m):
        if size[parent[p]] > sl[4]:
            giant[p] = 1
            n_giant += 1
    if n_giant > 0:
        parent = _group_pairs(x0w, pos, vel, cl, ph, gid, dt, forced, limits, giant)
    size[:] = 0
    for p in range(m):
        size[parent[p]] += 1  # parent[p]: the group's first member (roots are the least index)
    base = np.empty(m, np.int64)
    blk_of = np.empty(m, np.int64)
    starts = np.empty(m + 1, np.int64)
    n_blocks = 0
    fill = 0
    off = 0
    for p in range(m):
        if parent[p] != p:
            continue
        if n_blocks == 0 or (fill > 0 and fill + size[p] > cap):
            starts[n_blocks] = off
            n_blocks += 1
            fill = 0
        base[p] = off
        blk_of[p] = n_blocks - 1
        off += size[p]
        fill += size[p]
    starts[n_blocks] = m
    new = np.empty(m, np.int64)
    blk = np.empty(m, np.int64)
    for p in range(m):
        r = parent[p]
        new[p] = base[r]
        base[r] += 1
        blk[p] = blk_of[r]
    return new, blk, starts[:n_blocks + 1].copy()


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _near_band(ph):
    """2σ: how far beyond d a near pair's free-flight paths may be apart ("Near pairs"):
    the near filter's limit (_gather) and the far pairs' certificate (_conflicts)."""
    return 2.0 * ph.near_slack[0]


@njit(cache=True, no_cfunc_wrapper=True)
def _gather(x0w, st, cl, bc, ph, dt, d, blocked, forced, cs, filtered, threads):
    """The SubstepSet of this phase: the candidates (start ≤ 1) with their rows and their
    list neighbours, numbered in the list's cell order, block by block ("Blocks"; one
    block when not ``blocked``; groups joined by ``forced``, see _blocks), each block (each
    lane of one cut into lanes) with its candidates first (_candidates_first). Returns it, the
    candidates (member indices) by block and then by start, each block's first candidate
    (n_blocks + 1) and first member, and each member's index in cell order → its index in
    the set. ``cs``: the set of an earlier phase, reused (grown when too small: fresh
    arrays of ~1 kB per member cost a page fault per 4 kB at first touch, every step)."""
    n = x0w.shape[0]
    loc, start, nbr, nbr_count = ph.loc, ph.start, cl.nbr, cl.nbr_count
    # not the literal 0: typing passes _fill a Literal[int](0) count first, which compiled
    # it once more
    members = np.int64(0)
    rows = 0
    n_cand = 0
    order = cl.order
    for q in range(n):
        i = order[q]  # cell order: the neighbours' marks are near in memory
        if start[i] <= 1.0:
            n_cand += 1
            rows += nbr_count[i]
            if loc[i] < 0:
                loc[i] = 0
                members += 1
            for k in range(nbr_count[i]):
                j = nbr[i, k]
                if loc[j] < 0:
                    loc[j] = 0
                    members += 1
    gid = np.empty(members, np.int64)
    p = 0
    for q in range(n):
        g = order[q]
        if loc[g] >= 0:
            loc[g] = p
            gid[p] = g
            p += 1
    if blocked:
        new, blk, mstart = _blocks(x0w, st.pos, st.vel, cl, ph, gid, dt, d, ph.block_members[0], forced)
    else:
        new = np.arange(members)
        blk = np.zeros(members, np.int64)
        mstart = np.array([0, members])
    n_blocks = mstart.shape[0] - 1
    new = _candidates_first(new, mstart, gid, start, threads, ph)
    # room for some woken grains' rows and new neighbours (_give_row grows it if needed)
    cs = _grow(cs, members + members // 8 + 16, rows + rows // 8 + 8 * nbr.shape[1])
    cs.n_rows[0] = 0
    for p in range(members):
        loc[gid[p]] = new[p]
        cs.gid[new[p]] = gid[p]
        cs.block[new[p]] = blk[p]
    cs.n[0] = members
    cand = np.empty(n_cand, np.int64)
    key = np.empty(n_cand)
    _fill(as_tuple(cs, SubstepSet), members, x0w, as_tuple(st, GrainState), as_tuple(cl, ContactList),
          as_tuple(bc, BedContext), as_tuple(ph, ContactPhase), cand, key)
    if filtered:
        _near_pairs(as_tuple(cs, SubstepSet), cand, cl.grid.box, cl.grid.periodic, dt, d + _near_band(ph))
    by_start = cand[stable_argsort(key)]
    # stable counting sort by block: each block's candidates by start
    cstart = np.zeros(n_blocks + 1, np.int64)
    for t in range(n_cand):
        cstart[cs.block[by_start[t]] + 1] += 1
    for b in range(n_blocks):
        cstart[b + 1] += cstart[b]
    fill = cstart[:n_blocks].copy()
    out = np.empty(n_cand, np.int64)
    for t in range(n_cand):
        b = cs.block[by_start[t]]
        out[fill[b]] = by_start[t]
        fill[b] += 1
    return cs, out, cstart, mstart, new


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _lanes(threads, n_cand, ph):
    """On how many threads a block of ``n_cand`` candidates runs (_substep_part; "Blocks on
    several threads")."""
    return threads if n_cand >= ph.parallel_members[0] and threads >= ph.parallel_members[1] else 1


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _lane_start(q, m, lanes):
    """The first of lane q's members when m members are cut into ``lanes`` contiguous
    ranges (_substep_part runs them, _candidates_first orders each, and the drift's
    members to widen are listed from there)."""
    return np.int64(q) * m // lanes


@njit(cache=True, no_cfunc_wrapper=True)
def _candidates_first(new, mstart, gid, start, threads, ph):
    """``new`` (member in cell order → set index) with each block renumbered: its
    candidates first, then its other members (list neighbours only; two in three of a
    dense block's members, which the sub-steps only place: _kick_drift), each group in its
    old order. The sub-stepped members are then near in memory. A block cut into lanes
    (_substep_part) is renumbered so within each lane's range, as cut for the gathered
    members: the lanes keep their members (with the candidates first in the whole block,
    one lane would get nearly all the work). The blocks' ranges and the result are
    unchanged (the members may be done in any order: _forces); which members retire is not
    (_quiet_until)."""
    m = new.shape[0]
    inv = np.empty(m, np.int64)
    for p in range(m):
        inv[new[p]] = p
    out = new.copy()
    for b in range(mstart.shape[0] - 1):
        lo, hi = mstart[b], mstart[b + 1]
        n_cand = 0
        for t in range(lo, hi):
            n_cand += start[gid[inv[t]]] <= 1.0
        lanes = _lanes(threads, n_cand, ph)
        for q in range(lanes):
            t0 = lo + _lane_start(q, hi - lo, lanes)
            t1 = lo + _lane_start(q + 1, hi - lo, lanes)
            k = t0
            for first in (True, False):
                for t in range(t0, t1):
                    if (start[gid[inv[t]]] <= 1.0) == first:
                        out[inv[t]] = k
                        k += 1
    return out


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _fill(cs, members, x0w, st, cl, bc, ph, cand, key):
    """The paths of the set's members 0..members-1 and the rows of the candidates among
    them (their member indices and starts into ``cand`` and ``key``, in member order).
    On the tuples, compiled without reference counting: a StructRef's field is loaded and
    counted at every read, and the rows write a dozen fields per entry (0.57 → 0.38 µs per
    grain-step at 3.94 %). _scatter_set likewise (_near_pairs on the unpacked arrays)."""
    m = 0
    for a in range(members):
        _set_member(cs, a, cs.gid[a], x0w, st.pos, st.vel, st.spin, ph.start, cs.block[a])
    for a in range(members):  # after every path is in: a row reads its neighbours' (_set_row)
        g = cs.gid[a]
        if ph.start[g] <= 1.0:
            _set_row(cs, a, st, cl, bc, ph)
            cand[m] = a
            key[m] = ph.start[g]
            m += 1


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _near_pairs(cs, cand, box, per, dt, limit):
    """The row entries of the candidates ``cand`` whose free-flight paths come within
    ``limit`` over the step (_path_gap) or that are in contact from the last step (the
    near ones, nn of them) moved to the row's front, in row order, the far ones after them
    (_near_first; "Near pairs"). Each candidate writes only its own row: the candidates
    run on all threads."""
    # arrays unpacked before the parallel loop: Numba 0.68 drops writes made in a prange
    # body through a named tuple's arrays (flight/spheres.py)
    path, rs, rc, nbr, touch, nx, nn = cs.path, cs.rs, cs.rc, cs.nbr, cs.touch, cs.nx, cs.nn
    image, shear = cs.image, cs.shear
    for t in prange(cand.shape[0]):
        a = cand[t]
        r0 = rs[a]
        r1 = r0 + rc[a]
        m = 0
        for k in range(r0, r1):  # nx: the near entries from the front, the far ones from the back
            if touch[k] == 0 and _member_gap(path, a, nbr[k], box, per, dt) > limit:
                nx[r1 - 1 - (k - r0 - m)] = k
            else:
                nx[r0 + m] = k
                m += 1
        nn[a] = m
        if m < r1 - r0:
            _near_first(nbr, image, touch, shear, nx, r0, r1, m)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", _nrt=False)
def _near_first(nbr, image, touch, shear, nx, r0, r1, m):
    """Row r0..r1 with its m near entries first and its far ones after them, each in row
    order, so every sum over the near entries keeps its order (the same bits). ``nx``
    lists the near entries in row order from r0 and the far ones in reverse from r1 − 1
    (as _near_pairs finds them); the far ones are turned round, and the row then follows
    the permutation's cycles in place (a place done is marked by −(nx + 1)). Afterwards
    nx[p] is the entry that went to place p, i.e. where it came from (as _set_row wrote the
    row: entry k is list entry k − r0): _scatter_set writes the contact history back there."""
    p, q = r0 + m, r1 - 1
    while p < q:
        nx[p], nx[q] = nx[q], nx[p]
        p += 1
        q -= 1
    for p in range(r0, r1):
        k = nx[p]
        if k < 0 or k == p:
            continue
        b, i0, i1, i2 = nbr[p], image[p, 0], image[p, 1], image[p, 2]
        t, s0, s1, s2 = touch[p], shear[p, 0], shear[p, 1], shear[p, 2]
        q = p
        while k != p:
            nbr[q] = nbr[k]
            touch[q] = touch[k]
            for c in range(3):
                image[q, c] = image[k, c]
                shear[q, c] = shear[k, c]
            nx[q] = -k - 1
            q = k
            k = nx[q]
        nbr[q], image[q, 0], image[q, 1], image[q, 2] = b, i0, i1, i2
        touch[q], shear[q, 0], shear[q, 1], shear[q, 2] = t, s0, s1, s2
        nx[q] = -p - 1
    for p in range(r0, r1):
        if nx[p] < 0:
            nx[p] = -nx[p] - 1


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _far_slack(ph, d):
    """2σ less room for rounding: two deviations that add up to less than this cannot bring
    a far pair into touch (_near_pairs found its paths further apart than d + 2σ)."""
    return _near_band(ph) - 2e-9 * d


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _wide_dev2(ph, d):
    """|δx|² from which a member's far pairs are looked at (_widen): half the far slack,
    so that a pair of two members below it is certified by their deviations alone
    (_conflicts). A filter with no slack (σ = 0) has none to spare: its far pairs are left
    to _conflicts, which redoes the phase."""
    half = 0.5 * _far_slack(ph, d)
    return half * half if half > 0.0 else np.inf


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _widen(cs, a):
    """Member a's deviation has reached the near filter's slack ("Near pairs"): its row and
    those of its partners in its block are put back in list order with every entry near
    (_whole_row), so that each looks at the other from now on, and any far pair left is one
    of two members below the slack (certified by _conflicts without a redo). In list order:
    a pair that was far may touch now, and a row's sum then takes its terms in the order
    the unfiltered phase does (the same bits)."""
    cs.widened[0] += 1
    _whole_row(cs, a)
    blk = cs.block[a]
    for k in range(cs.rs[a], cs.rs[a] + cs.rc[a]):
        b = cs.nbr[k]
        if cs.block[b] == blk and cs.has_row[b] != 0:
            _whole_row(cs, b)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", _nrt=False)
def _whole_row(cs, a):
    """Member a's row (if _near_first reordered it) back in list order, every entry near
    (nn = rc): each entry swapped to the place nx says it came from until every place
    holds its own."""
    r0, r1 = cs.rs[a], cs.rs[a] + cs.rc[a]
    if cs.has_row[a] == 0 or cs.nn[a] == r1 - r0:
        return
    nbr, image, touch, shear, nx = cs.nbr, cs.image, cs.touch, cs.shear, cs.nx
    for p in range(r0, r1):
        while nx[p] != p:
            k = nx[p]
            nbr[p], nbr[k] = nbr[k], nbr[p]
            touch[p], touch[k] = touch[k], touch[p]
            nx[p], nx[k] = nx[k], nx[p]
            for c in range(3):
                image[p, c], image[k, c] = image[k, c], image[p, c]
                shear[p, c], shear[k, c] = shear[k, c], shear[p, c]
    cs.nn[a] = r1 - r0


@njit(cache=True, no_cfunc_wrapper=True)
def _give_row(cs, a, x0w, st, cl, bc, ph):
    """A row for member a (a woken list neighbour): its neighbours that are not members
    yet are appended first, in a's block. Returns the (possibly grown) set."""
    g = cs.gid[a]
    m = cl.nbr_count[g]
    cs = _grow(cs, cs.n[0] + m, cs.n_rows[0] + m)
    for k in range(m):
        j = cl.nbr[g, k]
        if ph.loc[j] < 0:
            b = cs.n[0]
            ph.loc[j] = b
            cs.n[0] = b + 1
            _set_member(cs, b, j, x0w, st.pos, st.vel, st.spin, ph.start, cs.block[a])
    _set_row(cs, a, st, cl, bc, ph)
    return cs


@njit(cache=True, no_cfunc_wrapper=True)
def _wake_up(cs, x0w, st, bc, model, cl, ph, s, dt, h, lo, hi, app, blk, flagged):
    """Activate every member of block blk not active that an active one touches (its
    deviation is exactly zero until now) and give it its forces at this sub-step; repeat
    for the members those touch. ``flagged``: how many members _forces listed in
    cs.flagged (one pass over the block, in its order), or -1: look through the block's
    members (a pass cut between threads). Returns the (possibly grown) set and how many
    were woken."""
    box, per = cl.grid.box, cl.grid.periodic
    d2 = model.diameter * model.diameter
    q_lo = 0
    q_hi = 0
    recalled = 0  # retired members forced again (already counted as active)
    first_round = True
    while True:
        # members flagged in this round: the force pass's at first, then the newly woken
        q_new = q_hi
        if not first_round:
            n_scan = q_hi - q_lo
        elif flagged >= 0:
            n_scan = flagged
        else:
            n_scan = _block_size(cs, lo, hi, app)
        for t in range(n_scan):
            if first_round:
                a = cs.flagged[t] if flagged >= 0 else _block_member(t, lo, hi, app)
            else:
                a = cs.queue[q_lo + t]
            if cs.active[a] == 0 or cs.wake[a] == 0:
                continue
            cs.wake[a] = 0
            for k in range(cs.rs[a], cs.rs[a] + cs.rc[a]):
                b = cs.nbr[k]
                if cs.active[b] == ACTIVE or cs.active[b] == CLAIMED or cs.block[b] != blk:
                    continue
                xj, yj, zj = _position_of(cs, b, s, dt)
                dxx = min_image(cs.cur[a, 0] - xj, box[0], per[0])
                dyy = min_image(cs.cur[a, 1] - yj, box[1], per[1])
                dzz = min_image(cs.cur[a, 2] - zj, box[2], per[2])
                if dxx * dxx + dyy * dyy + dzz * dzz < d2:
                    # claimed: activated below (a retired one is forced again)
                    cs.active[b] = CLAIMED if cs.active[b] == RETIRED else ACTIVE
                    cs.queue[q_new] = b
                    q_new += 1
        first_round = False
        if q_new == q_hi:
            break
        n_before = cs.n[0]
        for t in range(q_hi, q_new):
            b = cs.queue[t]
            if cs.active[b] == CLAIMED:
                _force_again(cs, b, s, dt, h, ph.retire_backoff[0])
                recalled += 1
                continue
            if cs.has_row[b] == 0:
                cs = _give_row(cs, b, x0w, st, cl, bc, ph)
            cs.active[b] = 0
            _activate(as_tuple(cs, SubstepSet), b, s, dt)
        v, sv, bv = as_tuple(cs, SubstepSet), as_tuple(st, GrainState), as_tuple(bc, BedContext)
        # the members just appended (woken grains' neighbours) have no position at s yet;
        # the woken ones keep theirs (_activate puts them on their path at s, as _at did)
        _positions(v, s, dt, n_before, v.n[0], v.n[0], np.int64(0), v.n[0] - n_before)
        for t in range(q_hi, q_new):
            # b alone (as members b..b and none appended): the compiled _forces, not a
            # second inlined copy of the force code (wake-ups are rare). Its flags are
            # run-time values (s < 0: False): a literal True or False would compile it once more
            b = v.queue[t]
            _forces(v, sv, bv, model, s, dt, h, b, b + 1, v.n[0], blk, np.int64(0), np.int64(1), 0.0, s < 0.0)
        q_lo = q_hi
        q_hi = q_new
    return cs, q_hi - recalled


# the parts of a sub-step (_substep_part); KICK_KICK_DRIFT: the previous sub-step's second
# half kick and this one's first part in one pass (one parallel launch less per sub-step)
KICK_DRIFT, FORCES, KICK, KICK_KICK_DRIFT = 0, 1, 2, 3


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _substep_part(part, cs, st, bc, model, s, dt, h, lo, hi, app, blk, lanes, per_lane, wide2):
    """One part of a sub-step of a large block (KICK_DRIFT, FORCES, KICK or
    KICK_KICK_DRIFT), its members cut into ``lanes`` contiguous ranges done in parallel.
    Every member's arithmetic is its own (_forces), so the result is that of one thread,
    bit for bit. Returns the count of _forces (FORCES), else 0. No member retires here
    (_quiet_until needs the members one after another; on two threads retiring them
    afterwards, one after another, measured slower, not faster). The members whose
    deviation reached ``wide2`` in the drift are widened after it, lane by lane, each in
    member order (_kick_drift; their rows are read first by the forces). ``per_lane``:
    scratch, each lane's count (grains woken by its forces, or members to widen)."""
    m = _block_size(cs, lo, hi, app)
    for q in prange(lanes):
        t0 = _lane_start(q, m, lanes)
        t1 = _lane_start(q + 1, m, lanes)
        v = as_tuple(cs, SubstepSet)  # the hot loops read tuples (grains/refs.py)
        if part == KICK_DRIFT or part == KICK_KICK_DRIFT:
            # the flags as run-time values (part < 0: False), as in _run_block
            per_lane[q] = _kick_drift(v, model, s, dt, h, lo, hi, app, t0, t1, part == KICK_KICK_DRIFT, part < 0,
                                      0.0, wide2)
        elif part == FORCES:
            per_lane[q] = _forces(v, as_tuple(st, GrainState), as_tuple(bc, BedContext), model, s, dt, h,
                                  lo, hi, app, blk, t0, t1, 0.0, part < 0)[0]
        else:
            _kick(v, model, h, lo, hi, app, t0, t1)
    if part == FORCES:
        return per_lane[:lanes].sum()
    if part == KICK_DRIFT or part == KICK_KICK_DRIFT:
        v = as_tuple(cs, SubstepSet)
        for q in range(lanes):
            t0 = _lane_start(q, m, lanes)
            for i in range(per_lane[q]):
                _widen(v, v.go[t0 + i])
    return 0


@njit(cache=True, no_cfunc_wrapper=True)
def _run_block(cs, cand, c0, c1, lo, hi, blk, x0w, st, bc, model, cl, ph, dt, n_sub, lanes):
    """All sub-steps of one block: members lo..hi-1, candidates cand[c0:c1]; members
    appended while it runs (woken grains' neighbours) belong to it. With ``lanes`` > 1
    each part of a sub-step runs over the members in parallel (_substep_part); joins and
    wake-ups stay serial. Returns the set, the grain-sub-steps done and the grains woken."""
    h = dt / n_sub
    app = cs.n[0]
    backoff = ph.retire_backoff[0]
    wide2 = _wide_dev2(ph, model.diameter)
    cs.retired[0] = 0
    cs.widened[0] = 0
    n_act = 0  # active members of the block
    done = 0
    woken = 0
    per_lane = np.zeros(max(lanes, 1), np.int64)  # each lane's count (_substep_part)
    first = np.int64(0)  # not the literal 0: that would compile the kernels once more
    listed, scanned = first == 0, first != 0  # True and False, likewise not literals
    # the sub-step kernels read tuples (grains/refs.as_tuple); the set's view is made
    # again whenever a wake-up may have grown the set
    v, sv, bv = as_tuple(cs, SubstepSet), as_tuple(st, GrainState), as_tuple(bc, BedContext)
    # set-up: forces at s = 0 of the grains in contact now, without advancing the
    # tangential springs (their state is that of the previous step's last sub-step)
    ptr, joined = _join(v, cand, c0, c1, 0.0, 0.0, dt)
    n_act += joined
    _positions(v, 0.0, dt, lo, hi, app, first, _block_size(v, lo, hi, app))
    n_woke = _forces(v, sv, bv, model, 0.0, dt, h, lo, hi, app, blk, first, _block_size(v, lo, hi, app), 0.0,
                     scanned)[0]
    if n_woke > 0:
        cs, k_w = _wake_up(cs, x0w, st, bc, model, cl, ph, 0.0, dt, h, lo, hi, app, blk, n_woke)
        n_act += k_w
        woken += k_w
        v = as_tuple(cs, SubstepSet)
    for k in range(n_sub):
        s_next = (k + 1) / n_sub
        # grains that may touch something before s_next join now (no force at s_k: they
        # cannot be touching anything yet)
        ptr, joined = _join(v, cand, ptr, c1, s_next, k / n_sub, dt)
        n_act += joined
        done += n_act
        # the previous sub-step's second half kick is done in this pass (from k = 1)
        if lanes > 1:
            part = KICK_KICK_DRIFT if k > 0 else KICK_DRIFT
            _substep_part(np.int64(part), cs, st, bc, model, s_next, dt, h, lo, hi, app, blk, lanes, per_lane,
                          wide2)
            n_woke = _substep_part(np.int64(FORCES), cs, st, bc, model, s_next, dt, h, lo, hi, app, blk,
                                   lanes, per_lane, wide2)
        else:
            m = _block_size(v, lo, hi, app)
            n_go = _kick_drift(v, model, s_next, dt, h, lo, hi, app, first, m, k > 0, listed, backoff, wide2)
            n_woke, left = _forces(v, sv, bv, model, s_next, dt, h, lo, hi, app, blk, first, n_go, backoff, listed)
            cs.retired[0] += left
        if n_woke > 0:
            cs, k_w = _wake_up(cs, x0w, st, bc, model, cl, ph, s_next, dt, h, lo, hi, app, blk,
                               n_woke if lanes == 1 else -1)
            n_act += k_w
            woken += k_w
            v = as_tuple(cs, SubstepSet)
    # the last sub-step's second half kick
    if lanes > 1:
        _substep_part(np.int64(KICK), cs, st, bc, model, 1.0, dt, h, lo, hi, app, blk, lanes, per_lane, wide2)
    else:
        _kick(v, model, h, lo, hi, app, first, _block_size(v, lo, hi, app))
    return cs, done, woken


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _group_of(cs, a, cell_of, forced, mstart):
    """A member (index in cell order) of member a's group; a member appended while its
    block ran (its group is not known) first joins every group of its block."""
    m0 = cell_of.shape[0]
    if a < m0:
        return cell_of[a]
    bl = cs.block[a]
    p = cell_of[mstart[bl]]
    for t in range(mstart[bl] + 1, mstart[bl + 1]):
        _join_groups(forced, p, cell_of[t])
    return p


@njit(cache=True, no_cfunc_wrapper=True)
def _conflicts(cs, dt, d, box, per, forced, new, mstart, far_slack):
    """The pairs of members that may have touched although their sub-steps did not look at
    each other: for every pair in an active member's row that is in another block
    ("Blocks") or far (not among its first nn, "Near pairs"), the free-flight paths come closer than d
    plus the largest deviations the two had. The groups of each such pair across blocks
    are joined in ``forced`` (an appended member, whose group is not known, joins its
    whole block). Returns their numbers (across blocks, far in one block): (0, 0)
    certifies the pass. A far pair whose two deviations add up to less than ``far_slack``
    (2σ of the near filter, less room for rounding) needs no gap: _near_pairs found it
    above d + 2σ, so it is above d + its deviations (at 3.94 % this skips nearly every far
    pair: 0.31 → 0.10 µs per grain-step, the same pairs certified)."""
    m0 = mstart[mstart.shape[0] - 1]
    cell_of = np.empty(0, np.int64)  # set index → index in cell order (the gather's), when needed
    # the set's arrays as locals: a StructRef's field is loaded (and counted) at every read
    path, active, dev_max, nn = cs.path, cs.active, cs.dev_max, cs.nn
    rs, rc, nbr, block = cs.rs, cs.rc, cs.nbr, cs.block
    n_bad = 0
    n_far = 0
    for a in range(cs.n[0]):
        if active[a] == 0:
            continue
        da = math.sqrt(dev_max[a])
        for k in range(rs[a], rs[a] + rc[a]):
            b = nbr[k]
            across = block[b] != block[a]
            if not across and k - rs[a] < nn[a]:
                continue
            db = math.sqrt(dev_max[b]) if active[b] != 0 else 0.0
            if not across and da + db < far_slack:
                continue  # a far pair's paths stay further apart than d + 2σ (_near_pairs): certified
            gap = _member_gap(path, a, b, box, per, dt)
            if gap - da - db > d * (1.0 + 1e-9):
                continue
            if not across:
                n_far += 1
                continue
            n_bad += 1
            if forced.shape[0] != m0:
                continue  # no forest to join in (the caller redoes the phase as one block)
            if cell_of.shape[0] == 0:
                cell_of = np.empty(m0, np.int64)
                for p in range(m0):
                    cell_of[new[p]] = p
            _join_groups(forced, _group_of(cs, a, cell_of, forced, mstart), _group_of(cs, b, cell_of, forced, mstart))
    return n_bad, n_far


@njit(cache=True, no_cfunc_wrapper=True)
def _release(cs, st, ph):
    """Undo a blocked pass that failed _conflicts: the grain arrays were not written, except
    the jump records of bed impacts and the set's membership marks."""
    for a in range(cs.n[0]):
        g = cs.gid[a]
        ph.loc[g] = -1
        if cs.has_row[a] != 0:
            st.jump_buf_n[g] = cs.jump_n0[a]
            st.jump_count[g] = cs.jump_c0[a]


@njit(cache=True, no_cfunc_wrapper=True)
def _scatter(cs, st, cl, bc, ph, skin_half):
    """_scatter_set on the tuples of the set, the grains, the list, the bed and the phase."""
    return _scatter_set(as_tuple(cs, SubstepSet), as_tuple(st, GrainState), as_tuple(cl, ContactList),
                        as_tuple(bc, BedContext), as_tuple(ph, ContactPhase), skin_half)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _scatter_set(cs, st, cl, bc, ph, skin_half):
    """End of the phase: what the sub-steps changed back into the grain arrays; for the
    grains that had a contact the deviations are added, and the fluid re-sampled and
    the Basset history restarted (module docstring). Marks the sub-stepped grains in
    ph.active / ph.act and returns those whose path may have left the list's reach
    (overruns)."""
    over = 0
    na = 0
    pos, vel, spin = st.pos, st.vel, st.spin
    for a in range(cs.n[0]):
        g = cs.gid[a]
        ph.loc[g] = -1
        if cs.active[a] == 0:
            continue
        ph.active[g] = 1
        ph.act[na] = g
        na += 1
        r0 = cs.rs[a]
        for k in range(r0, r0 + cs.rc[a]):
            e = cs.nx[k] - r0  # the entry's place in the list's row (_near_pairs)
            cl.touch[g, e] = cs.touch[k]
            for c in range(3):
                cl.shear[g, e, c] = cs.shear[k, c]
        cl.collisions[g] = cs.collisions[a]
        cl.max_overlap[g] = cs.max_overlap[a]
        cl.n_touch[g] = cs.n_touch[a]
        ph.contact_substeps[g] = cs.contact_substeps[a]
        ph.overlap_sum[g] = cs.overlap_sum[a]
        ph.bed_overlap_max[g] = cs.bed_overlap_max[a]
        for k in range(BED_SLOTS):
            bc.slot_id[g, k] = cs.slot_id[a, k]
            for c in range(3):
                bc.slot_c[g, k, c] = cs.slot_c[a, k, c]
                bc.slot_shear[g, k, c] = cs.slot_shear[a, k, c]
        bc.in_bed[g] = cs.in_bed[a]
        bc.last_contact[g] = cs.last_contact[a]
        st.impacts[g] = cs.impacts[a]
        st.jump_t0[g] = cs.jump_t0[a]
        st.jump_x0[g] = cs.jump_x0[a]
        st.jump_ymax[g] = cs.jump_ymax[a]
        if ph.ref_bound[g] + math.sqrt(cs.dev_max[a]) > skin_half:
            over += 1
        if cs.touched[a] != 0:
            for c in range(3):
                pos[g, c] += cs.dev[a, c]
                vel[g, c] += cs.dev[a, 3 + c]
                spin[g, c] += cs.dev[a, 6 + c]
                ph.deviation[g, c] = cs.dev[a, c]
                ph.deviation[g, 3 + c] = cs.dev[a, 3 + c]
            st.fresh[g] = 0
            history_mark_impact(st.hist_meta[g])  # the next step takes the slip step (physics/history.py)
        # the bed pass skips the grains sub-stepped here, touched or not: the jump's highest
        # point is kept here (a grain sub-stepped through its apex without a contact kept the
        # height of its last bed contact before)
        if pos[g, 1] > st.jump_ymax[g]:
            st.jump_ymax[g] = pos[g, 1]
    ph.n_act[0] = na
    return over


@njit(cache=True, no_cfunc_wrapper=True)
def _with_skin(cl, skin):
    """The ContactList with another skin (cells unchanged: they must be wide enough)."""
    return ContactList(cl.grid, 1.0 + skin, skin, cl.cell_of, cl.cell_start,
                       cl.cell_count, cl.order, cl.ref_pos, cl.nbr, cl.nbr_count, cl.shear, cl.touch, cl.nbr2,
                       cl.nbr_count2, cl.shear2, cl.touch2, cl.n_touch, cl.collisions, cl.max_overlap, cl.builds)



@njit(cache=True, no_cfunc_wrapper=True)
def soft_contact_phase(state, x0w, model, cl, phase, bed, t0, step, dt, n_sub, cs, threads=1, base_skin=0.0):
    """Phase 2 of the module docstring for all grains: the free flight (x₀ in ``x0w``
    (N, 9) = w.x0, x₁ in ``state``, a GrainState; ``phase`` a ContactPhase, ``bed`` a
    BedContext) of step ``step`` (from t0) corrected by soft contacts
    with grains and the bed in ``n_sub`` sub-steps. ``ph.active`` says afterwards which
    grains were sub-stepped (their bed is done; the bed pass must skip them). ``cs``: the
    SubstepSet the previous phase returned (or ``empty_substep_set()``), reused. ``threads``:
    Numba's thread count (``numba.get_num_threads()``, from Python: called in compiled code
    it makes the kernel uncachable); on more than one a large block's sub-steps run over
    its members on all of them (_substep_part). ``base_skin`` > 0: a skin widened for a
    fast grain narrows back towards it at a rebuild ("Neighbour list"). Returns the ContactList to keep (it may
    have been rebuilt) and the set to pass next time."""
    # one pointer each for the state tuples in every kernel below (grains/refs.py)
    st, ph, bc = GrainStateRef(*state), ContactPhaseRef(*phase), BedContextRef(*bed)
    pos, vel = st.pos, st.vel
    bc.t0[0] = t0
    bc.ints[1] = step
    tic = wall_clock() if ph.clocks.shape[0] > 0 else 0.0  # profiling (ContactPhase.clocks)
    n = pos.shape[0]
    skin_half = 0.5 * cl.skin
    drift = _drift(x0w, pos, cl.ref_pos, cl.grid.box, cl.grid.periodic)
    worst = _reach(x0w, pos, vel, dt, cl, ph, drift)
    if worst > skin_half - LIST_ROOM:
        for i in range(n):
            for a in range(3):
                ph.x0pos[i, a] = x0w[i, a]
        drift[:, :] = 0.0  # the list is now built at x₀
        fastest = 0.0
        for i in range(n):
            fastest = max(fastest, ph.reach[i])
        if base_skin > 0.0 and cl.skin > base_skin and 2.5 * fastest <= base_skin:
            # the grains that widened the skin have slowed down: back to the case's skin,
            # with the margin the widening gives
            cl = _with_skin(cl, base_skin)
            skin_half = 0.5 * cl.skin
        cl = rebuild(ph.x0pos, cl)
        ph.counters[LIST_REBUILDS] += 1
        for i in range(n):
            ph.ref_bound[i] = ph.reach[i]  # the list is now built at x₀
        if fastest > skin_half:
            # a grain faster than the skin allows: grow the skin as far as the cells allow
            widest = min(cl.grid.size[0], min(cl.grid.size[1], cl.grid.size[2])) - model.diameter
            skin = min(2.5 * fastest, widest)
            if skin > cl.skin:
                cl = _with_skin(cl, skin)
                cl = rebuild(ph.x0pos, cl)
                skin_half = 0.5 * cl.skin
            for i in range(n):
                if ph.reach[i] > skin_half:  # still too fast: a contact might be missed
                    ph.counters[OVERRUNS] += 1
    tic = _lap(ph, CLOCK_LIST, tic)
    lst = ContactListRef(*cl)  # the list (fixed from here on) as one pointer (grains/refs.py)
    _engage(x0w, pos, vel, dt, model, lst, ph, bc, drift[0])
    tic = _lap(ph, CLOCK_ENGAGE, tic)
    ph.n_act[0] = 0
    n_cand = 0
    for i in range(n):
        if ph.start[i] <= 1.0:
            n_cand += 1
    if n_cand == 0:
        return cl, cs
    # the candidates and their neighbours, in compact cell-ordered arrays (module
    # docstring, "Memory layout"), block by block ("Blocks"); candidates join by the
    # time they may first touch something (docstring: who is sub-stepped)
    d = model.diameter
    box, per = lst.grid.box, lst.grid.periodic
    wakes0, done0, retired0 = ph.counters[WAKES], ph.counters[SUBSTEPPED], ph.counters[RETIRED_SUBSTEPS]
    widened0 = ph.counters[WIDENED]
    forced = np.empty(0, np.int64)  # groups joined after a failed pass (_conflicts)
    passes = 0
    filtered = ph.near_slack[0] < np.inf  # far pairs not looked at ("Near pairs")
    blocking = step >= ph.unblocked[0]  # else the last blocks were one giant block ("Blocks")
    while True:
        cs, cand, cstart, mstart, new = _gather(x0w, st, lst, bc, ph, dt, d, blocking and passes <= MERGED_PASSES,
                                                forced, cs, filtered, threads)
        tic = _lap(ph, CLOCK_GATHER, tic)
        n_blocks = mstart.shape[0] - 1
        if blocking and passes == 0 and 2 * _largest_block(mstart) > mstart[n_blocks]:
            ph.unblocked[0] = step + ph.unblocked[1]  # one block holds most members
        for b in range(n_blocks):  # one after another; a large one on all threads from LANE_THREADS (_lanes)
            c0, c1 = cstart[b], cstart[b + 1]
            if c1 == c0:
                continue
            lanes = _lanes(threads, c1 - c0, ph)
            cs, done, woken = _run_block(cs, cand, c0, c1, mstart[b], mstart[b + 1], b, x0w, st, bc, model, lst,
                                         ph, dt, n_sub, lanes)
            ph.counters[SUBSTEPPED] += done
            ph.counters[RETIRED_SUBSTEPS] += cs.retired[0]
            ph.counters[WIDENED] += cs.widened[0]
            ph.counters[WAKES] += woken
            if lanes > 1:
                ph.counters[PARALLEL_BLOCKS] += 1
        ph.counters[BLOCKS] += n_blocks
        tic = _lap(ph, CLOCK_SUBSTEPS, tic)
        if n_blocks == 1 and not filtered:
            break
        if n_blocks > 1 and forced.shape[0] == 0:
            forced = np.arange(mstart[n_blocks])  # the same members in every pass
        joined = forced.copy() if filtered else forced
        n_bad, n_far = _conflicts(cs, dt, d, box, per, joined, new, mstart, _far_slack(ph, d))
        tic = _lap(ph, CLOCK_CONFLICTS, tic)
        if n_bad == 0 and n_far == 0:
            break
        if n_far > 0:
            # a far pair came near: this pass again without the filter (its sub-steps, and
            # so its crossings, are not those of the unfiltered pass: nothing joined, its
            # blocks not counted twice)
            filtered = False
            ph.counters[REDONE_FAR] += 1
            ph.counters[BLOCKS] -= n_blocks
        else:
            # a deflected grain came near one of another block: redo the phase with the two
            # groups joined (after MERGED_PASSES such passes, as one block)
            forced = joined
            passes += 1
            ph.counters[REDONE_UNBLOCKED if passes > MERGED_PASSES else REDONE_MERGED] += 1
        _release(cs, st, ph)
        ph.counters[WAKES] = wakes0
        ph.counters[SUBSTEPPED] = done0
        ph.counters[RETIRED_SUBSTEPS] = retired0
        ph.counters[WIDENED] = widened0
        tic = _lap(ph, CLOCK_CONFLICTS, tic)
    over = _scatter(cs, st, lst, bc, ph, skin_half)
    if over > 0:
        # a grain may have left the list's reach: look for pairs in contact now that the
        # list does not hold (an actual miss), with fresh cells
        ph.counters[OVERRUNS] += over
        ph.counters[MISSED] += _missed_contacts(st.pos, cl)
    _lap(ph, CLOCK_SCATTER, tic)
    return cl, cs


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _largest_block(mstart):
    """Members of the largest block (blocks' first members ``mstart``, n_blocks + 1)."""
    most = 0
    for b in range(mstart.shape[0] - 1):
        most = max(most, mstart[b + 1] - mstart[b])
    return most


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _lap(ph, part, tic):
    """Profiling: the wall time since ``tic`` added to ``ph.clocks[part]``; returns the time
    now (``tic`` itself, and no clock read, when ``clocks`` is empty)."""
    if ph.clocks.shape[0] == 0:
        return tic
    now = wall_clock()
    ph.clocks[part] += now - tic
    return now


@njit(cache=True, no_cfunc_wrapper=True)
def _missed_contacts(pos, cl):
    """Pairs closer than d at ``pos`` that are not in each other's neighbour list."""
    g = cl.grid
    n = pos.shape[0]
    cell_of = np.empty(n, np.int64)
    start = np.empty(cl.cell_start.shape[0], np.int64)
    count = np.empty(cl.cell_count.shape[0], np.int64)
    order = np.empty(n, np.int64)
    build_cells(pos, g, cell_of, start, count, order)
    cells = np.empty(27, np.int64)
    missed = 0
    for i in range(n):
        m = stencil_cells(g, cell_of[i], cells)
        for c in range(m):
            for q in range(start[cells[c]], start[cells[c]] + count[cells[c]]):
                j = order[q]
                if j <= i:
                    continue
                dx = min_image(pos[i, 0] - pos[j, 0], g.box[0], g.periodic[0])
                dy = min_image(pos[i, 1] - pos[j, 1], g.box[1], g.periodic[1])
                dz = min_image(pos[i, 2] - pos[j, 2], g.box[2], g.periodic[2])
                if dx * dx + dy * dy + dz * dz >= 1.0:
                    continue
                listed = False
                for k in range(cl.nbr_count[i]):
                    if cl.nbr[i, k] == j:
                        listed = True
                if not listed:
                    missed += 1
    return missed


@njit(cache=True, no_cfunc_wrapper=True)
def hard_contact_phase(st, cl, restitution, friction, before):
    """Binary hard-sphere impulses at the end-of-flight positions, then the overlaps
    removed (contacts/pairs.py: hard_sphere_collisions, push_apart; no centre pushed below
    the bed top). Grains that collided restart their Basset history; grains moved take a
    fresh fluid sample at their new position next step. ``before`` (N,) int64 scratch.
    Returns the collisions."""
    n = st.pos.shape[0]
    for i in range(n):
        before[i] = cl.collisions[i]
    count = hard_sphere_collisions(st.pos, st.vel, st.spin, cl, restitution, friction, 1.0)
    if count > 0:
        for i in range(n):
            if cl.collisions[i] != before[i]:
                history_mark_impact(st.hist_meta[i])  # the next step takes the slip step (physics/history.py)
    for i in range(n):
        before[i] = 0
    push_apart(st.pos, cl, 1.0, 0.5, before)
    for i in range(n):
        if before[i] != 0:
            st.fresh[i] = 0
    return count
