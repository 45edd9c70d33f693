"""The model's noise sampler (gift_theory._random): the cipher is JAX's Threefry-2x32-20 bit
for bit, and every law has the distribution it claims.

Distribution tests are Kolmogorov-Smirnov (and moment) tests at level 1e-4 per assertion,
on 2e5 draws: a correct sampler fails one with probability 1e-4, whatever the seed."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from jax.extend.random import threefry_2x32
from scipy import stats

# private: the sampler's cipher and laws, which every public draw goes through but none isolates
from gift_theory import _random as R

ALPHA = 1e-4
N = 200_000


@given(k0=st.integers(0, 2**32 - 1), k1=st.integers(0, 2**32 - 1), start=st.integers(0, 2**32 - 64))
def test_cipher_is_jax_threefry_bit_for_bit(k0, k1, start):
    key = jnp.array([k0, k1], jnp.uint32)
    count = (jnp.arange(32, dtype=jnp.uint32) + jnp.uint32(start))
    ref = np.asarray(threefry_2x32(key, count))  # JAX enciphers (first half, second half)
    y0, y1 = R.threefry2x32(key[0], key[1], count[:16], count[16:])
    assert np.array_equal(np.concatenate([y0, y1]), ref)


def test_same_key_same_numbers_and_key_forms_agree():
    typed = jax.random.key(7)
    raw = jax.random.PRNGKey(7)
    a = np.asarray(R.normal(typed, (5, 3)))
    assert np.array_equal(a, np.asarray(R.normal(raw, (5, 3))))
    assert np.array_equal(a, np.asarray(jax.jit(lambda k: R.normal(k, (5, 3)))(typed)))
    assert not np.array_equal(a, np.asarray(R.normal(jax.random.key(8), (5, 3))))


def test_bits_are_uniform_bytes():
    b = np.asarray(R.bits(jax.random.key(1), (N,))).view(np.uint8)
    counts = np.bincount(b, minlength=256)
    assert stats.chisquare(counts).pvalue > ALPHA
    # each of the 32 bit positions is a fair coin
    words = np.asarray(R.bits(jax.random.key(2), (N,)))
    ones = np.array([((words >> i) & 1).sum() for i in range(32)])
    z = (ones - N / 2) / np.sqrt(N / 4)
    assert np.abs(z).max() < stats.norm.isf(ALPHA / 64)


@pytest.mark.parametrize("law, ref, kurt", [
    (R.normal, stats.norm(), 0.0),
    (R.laplace, stats.laplace(scale=np.sqrt(0.5)), 3.0),
    (R.uniform_law, stats.uniform(-np.sqrt(3), 2 * np.sqrt(3)), -1.2),
])
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_laws(law, ref, kurt, dtype):
    with jax.enable_x64(dtype == "float64"):
        z = np.asarray(law(jax.random.key(3), (N,), jnp.dtype(dtype)), np.float64)
    assert z.dtype == np.float64 and np.all(np.isfinite(z))
    assert stats.kstest(z, ref.cdf).pvalue > ALPHA
    zq = stats.norm.isf(ALPHA / 2)
    assert abs(z.mean()) < zq * z.std() / np.sqrt(N)
    # unit variance: se of the sample variance is sqrt((m4 - 1) / N) for unit variance
    assert abs(z.var() - 1.0) < zq * np.sqrt((3.0 + kurt - 1.0) / N) + 1e-3


def test_float64_draws_have_float64_resolution():
    with jax.enable_x64(True):
        u = np.asarray(R.uniform(jax.random.key(4), (10_000,), jnp.float64))
    assert u.dtype == np.float64
    assert np.all((u > -1) & (u < 1))
    # a float32-resolution sampler would put every value on the 2^-22 grid
    off_grid = np.abs(u * 2**22 - np.round(u * 2**22)) > 1e-3
    assert off_grid.mean() > 0.99


def test_streams_of_different_keys_and_sites_are_uncorrelated():
    a = np.asarray(R.normal(jax.random.key(5), (N,)), np.float64)
    b = np.asarray(R.normal(jax.random.fold_in(jax.random.key(5), 1), (N,)), np.float64)
    # the second half of a draw (second cipher words) against the first
    r_ab = np.corrcoef(a, b)[0, 1]
    r_half = np.corrcoef(a[: N // 2], a[N // 2:])[0, 1]
    bound = stats.norm.isf(ALPHA / 2) / np.sqrt(N // 2)
    assert abs(r_ab) < bound and abs(r_half) < bound


def test_odd_sizes_and_empty_shapes():
    for shape in ((1,), (3,), (7, 5), (0,), (2, 0, 3)):
        z = R.normal(jax.random.key(6), shape)
        assert z.shape == shape
    small = np.asarray(R.normal(jax.random.key(6), (7, 5)))
    assert len(np.unique(small)) == small.size


def test_float32_normal_is_the_inverse_cdf_to_a_few_ulps_everywhere():
    """Every one of the 2^23 float32 uniforms maps to within 8 ulps of sqrt(2) erfinv(u),
    monotonically (exhaustive: no sampling, so no tolerance from chance)."""
    from scipy import special

    m = np.arange(2**23, dtype=np.uint32)
    z = np.asarray(jax.jit(R._normal32)(jnp.asarray(m << np.uint32(9))), np.float64)
    exact = np.sqrt(2.0) * special.erfinv((m + 0.5) * 2.0**-22 - 1.0)
    ulps = np.abs(z - exact) / np.spacing(np.abs(exact).astype(np.float32)).astype(np.float64)
    assert ulps.max() <= 8.0
    assert np.all(np.diff(z) >= 0)
    assert np.array_equal(z, -z[::-1])  # exactly symmetric


@pytest.mark.slow
@pytest.mark.parametrize("law", R.ROW_LAWS)
@pytest.mark.parametrize("shape", [(13, 7, 3), (8, 5), (1, 1), (6, 1, 4, 2)])
def test_a_block_of_rows_is_the_whole_draw_s_rows_bit_for_bit(law, shape):
    """The lab makes a large file's model shots a block of inputs at a time; each block of a draw
    must be the whole draw's rows bit for bit, found from the stream's layout alone (word w is
    the first output of counter w in the first half, the second output of counter w - ceil(n/2)
    after it; an odd word count straddles the two). Rows past the end are padding. Private: the
    block sampler's only caller is the lab's shot blocks, whose own test cannot isolate it."""
    key = jax.random.fold_in(jax.random.key(7), 3)
    whole = np.asarray(getattr(R, law)(key, shape))
    for size in (1, 3, shape[0]):
        for start in range(0, shape[0], size):
            got = np.asarray(R.rows(law, key, shape, start, size))
            assert got.shape == (size,) + shape[1:] and np.all(np.isfinite(got))
            np.testing.assert_array_equal(got[:shape[0] - start], whole[start:start + size])
    with pytest.raises(ValueError, match="law"):
        R.rows("cauchy", key, shape, 0, 1)


def test_padded_lengths_cover_every_draw_with_at_most_half_padding():
    """The ladder 1024, 1536, 2048, 3072, ... : every length at least the draw, at most 1.5 times
    it above 1024 words, and draws above the cap get none (their own shape's program)."""
    sizes = [R.padded_size(n) for n in range(1, 70_000, 7)]
    assert all(s >= n and (n <= 1024 or s <= 1.5 * n) for n, s in zip(range(1, 70_000, 7), sizes))
    assert sorted(set(sizes)) == [1024, 1536, 2048, 3072, 4096, 6144, 8192, 12288, 16384, 24576, 32768, 49152,
                                  65536, 98304]
    assert R.padded_size(R.PADDED_MAX_WORDS) == R.PADDED_MAX_WORDS and R.padded_size(R.PADDED_MAX_WORDS + 1) is None


@pytest.mark.parametrize("x64", [False, True])
def test_a_site_drawn_by_a_padded_program_is_its_own_shape_s_draw_bit_for_bit(x64):
    """compiled_site_draws makes a float32 draw of a built-in law by the program of its padded
    length and keeps the first words: the numbers must be those of the site's own-shape sampler
    (site_draws, jitted), for odd and even word counts, across a length step, for every built-in
    law and for a plugin's law (drawn by its own-shape program), and so must site_draws' called
    outside a trace (which draws through the padded program). Private: the padding is invisible
    by design, so no public output can tell the two programs apart."""
    from gift_theory import _model as M
    from gift_theory.effects import REGISTRY

    key = jax.random.fold_in(jax.random.key(3), 11)
    laws = [None, REGISTRY["laplace"](), REGISTRY["uniform"]()]
    with jax.enable_x64(x64):
        for shape in [(1,), (3, 1), (13, 7, 3), (41, 8, 5), (1025,), (2, 769), (80, 48, 4, 8)]:
            for law in laws:
                for name in ("a0", "w2"):
                    got = M.compiled_site_draws(key, name, shape, law)
                    own = jax.jit(M.site_draws, static_argnums=(1, 2, 3))(key, name, shape, law)
                    eager = M.site_draws(key, name, shape, law)  # outside a trace: the padded program too
                    assert got.shape == eager.shape == shape and got.dtype == eager.dtype == jnp.float32
                    np.testing.assert_array_equal(np.asarray(got).view(np.uint32), np.asarray(own).view(np.uint32))
                    np.testing.assert_array_equal(np.asarray(eager).view(np.uint32), np.asarray(own).view(np.uint32))
    with pytest.raises(ValueError, match="law"):
        R.tagged_flat("cauchy", key, 1, 4, 1024)
    with pytest.raises(ValueError, match="fit"):
        R.tagged_flat("normal", key, 1, 2000, 1024)


@pytest.mark.parametrize("make_key", [lambda: jax.random.PRNGKey(3), lambda: jax.random.key(9),
                                      lambda: jax.random.fold_in(jax.random.PRNGKey(7), 5),
                                      lambda: jax.random.key(4, impl="rbg")])
def test_uniform01_is_jax_random_uniform_bit_for_bit(make_key):
    """The lab's randomised PIT draws jax.random.uniform's numbers by a program of a padded length:
    the same numbers, shape and dtype for Threefry keys (raw and typed), an odd, an empty and a
    multi-axis shape; an rbg key (other bits) and 64-bit mode (float64) go to JAX itself.
    Private: the padding is invisible by design."""
    key = make_key()
    for shape in [(5,), (7, 3), (0, 3), (80, 48, 16)]:
        ref = np.asarray(jax.random.uniform(key, shape))
        got = R.uniform01(key, shape)
        assert got.shape == ref.shape and got.dtype == ref.dtype
        np.testing.assert_array_equal(got.view(np.uint32), ref.view(np.uint32))
    with jax.enable_x64(True):
        ref = np.asarray(jax.random.uniform(key, (6, 2)))
        got = R.uniform01(key, (6, 2))
        assert got.dtype == np.float64 and np.array_equal(got, ref)


_KEYS = [lambda: jax.random.PRNGKey(3), lambda: jax.random.key(9), lambda: jax.random.fold_in(jax.random.PRNGKey(7), 5),
         lambda: jax.random.key(4, impl="rbg")]


@pytest.mark.parametrize("make_key", _KEYS)
def test_jax_s_samplers_by_padded_programs_are_jax_s_numbers_bit_for_bit(make_key):
    """Initial weights, teacher data, device errors, the offset null's truths, the session's split
    and the noise floor's halves draw jax.random's uniform, normal and permutation numbers by
    programs of a padded length (no program per shape): the same values, shapes and dtypes for
    Threefry keys (raw and typed) over odd, empty and multi-axis shapes, bounds that do not
    round to float32 exactly, permutations of one and of two sorting rounds (n > 1625), and the
    halves' permutation of every input's key of a split; an rbg key, 64-bit mode and a draw
    inside a traced function go to JAX itself. Private: the padding is invisible by design."""
    key = make_key()

    def same(got, ref):
        ref = np.asarray(ref)
        got = np.asarray(got)
        assert got.shape == ref.shape and got.dtype == ref.dtype
        np.testing.assert_array_equal(got.view(np.uint8), ref.view(np.uint8))

    for shape in [(5,), (7, 3), (0, 3), (32, 16), (80, 48, 4)]:
        for lo, hi in [(0.0, 1.0), (-0.433, 0.433), (-np.sqrt(6 / 48), np.sqrt(6 / 48)), (2.0, 2.5)]:
            same(R.uniform_like_jax(key, shape, jnp.float32, lo, hi), jax.random.uniform(key, shape, jnp.float32, lo, hi))
        same(R.normal_like_jax(key, shape), jax.random.normal(key, shape))
        same(R.normal_like_jax(key, shape, jnp.float32), jax.random.normal(key, shape, jnp.float32))
    for n in [1, 2, 17, 240, 1625, 1626, 5000]:
        same(R.permutation(key, n), jax.random.permutation(key, n))
    shuffle = jax.jit(lambda k, n, r: jax.vmap(lambda kk: jax.random.permutation(kk, r))(jax.random.split(k, n)),
                      static_argnums=(1, 2))
    for n, r in [(1, 1), (3, 2), (80, 48), (7, 1626)]:
        same(R.split_permutations(key, n, r), shuffle(key, n, r))
    with jax.enable_x64(True):
        same(R.uniform_like_jax(key, (6, 2), None, -1.0, 1.0), jax.random.uniform(key, (6, 2), None, -1.0, 1.0))
        same(R.normal_like_jax(key, (6, 2)), jax.random.normal(key, (6, 2)))
        same(R.permutation(key, 9), jax.random.permutation(key, 9))  # int64 there
        same(R.split_permutations(key, 3, 5), shuffle(key, 3, 5))
    traced = jax.jit(lambda k: (R.uniform_like_jax(k, (9,), jnp.float32, -0.5, 0.5), R.normal_like_jax(k, (9,))))(key)
    same(traced[0], jax.random.uniform(key, (9,), jnp.float32, -0.5, 0.5))
    same(traced[1], jax.random.normal(key, (9,)))


def test_jax_s_samplers_compile_one_program_per_padded_length_not_per_shape():
    """Why a private test: the point of the padded programs is that draws of many shapes share
    one compiled program (a program per shape cost the suite some 400 compilations). Five shapes
    of 700 to 1024 words, drawn from one key, leave one program each in the uniform's, the
    normal's and the shuffle's caches."""
    key = jax.random.PRNGKey(11)
    R._uniform_flat.clear_cache()
    R._normal_flat.clear_cache()
    R._bits_flat.clear_cache()
    for shape in [(700,), (35, 21), (1024,), (8, 100), (3, 5, 50)]:
        R.uniform_like_jax(key, shape, jnp.float32, -1.0, 1.0)
        R.normal_like_jax(key, shape)
        R.permutation(key, int(np.prod(shape)))
    assert R._uniform_flat._cache_size() == 1
    assert R._normal_flat._cache_size() == 1
    assert R._bits_flat._cache_size() == 1
