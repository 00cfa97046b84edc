"""GMR (eqs. 14-17): closed form, the gmr package, batches, bad input."""

import gmr
import numpy as np
import pytest

from hemg_drake.learning.gmr import Gmr, gaussian_log_pdf


def random_mixture(rng, n_states, n_dims):
    factors = rng.standard_normal((n_states, n_dims, n_dims))
    return dict(
        priors=rng.dirichlet(np.ones(n_states)),
        means=rng.standard_normal((n_states, n_dims)),
        covariances=factors @ factors.transpose(0, 2, 1) + 0.3 * np.eye(n_dims),
    )


def test_single_gaussian_equals_the_closed_form_conditional():
    rng = np.random.default_rng(0)
    mixture = random_mixture(rng, 1, 5)
    inputs, outputs = [3, 0], [1, 4]  # an arbitrary, unordered split
    model = Gmr(**mixture, input_dims=inputs, output_dims=outputs).fit()
    x = rng.standard_normal(2)

    mu, sigma = mixture["means"][0], mixture["covariances"][0]
    s_ii_inverse = np.linalg.inv(sigma[np.ix_(inputs, inputs)])
    s_oi = sigma[np.ix_(outputs, inputs)]
    expected_mean = mu[outputs] + s_oi @ s_ii_inverse @ (x - mu[inputs])
    expected_cov = sigma[np.ix_(outputs, outputs)] - s_oi @ s_ii_inverse @ s_oi.T

    mean, cov = model.predict(x)
    np.testing.assert_allclose(mean, expected_mean, rtol=1e-12)
    np.testing.assert_allclose(cov, expected_cov, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("inputs", [[0], [1, 3], [4, 0, 2]])
def test_mixture_agrees_with_the_gmr_package(inputs):
    rng = np.random.default_rng(len(inputs))
    mixture = random_mixture(rng, 4, 5)
    model = Gmr(**mixture, input_dims=inputs).fit()
    reference = gmr.GMM(n_components=4, random_state=0, **mixture)
    queries = rng.standard_normal((6, len(inputs)))

    means, covs = model.predict(queries)
    np.testing.assert_allclose(means, reference.predict(np.array(inputs), queries), rtol=1e-8)
    for query, mean, cov in zip(queries, means, covs):
        conditional = reference.condition(np.array(inputs), query)
        np.testing.assert_allclose(model.responsibilities(query), conditional.priors, rtol=1e-8)
        collapsed = conditional.to_mvn()
        np.testing.assert_allclose(mean, collapsed.mean, rtol=1e-8)
        np.testing.assert_allclose(cov, collapsed.covariance, rtol=1e-8, atol=1e-12)


def test_batch_equals_single_queries_and_weights_can_be_given():
    rng = np.random.default_rng(5)
    model = Gmr(**random_mixture(rng, 3, 4), input_dims=[0, 1]).fit()
    queries = rng.standard_normal((5, 2))
    weights = rng.dirichlet(np.ones(3), size=5)
    means, covs = model.predict(queries, weights=weights)
    for k in range(5):
        mean, cov = model.predict(queries[k], weights=weights[k])
        np.testing.assert_allclose(means[k], mean, rtol=1e-13)
        np.testing.assert_allclose(covs[k], cov, rtol=1e-13)
        # With given weights the mean is the weighted sum of component conditionals (eq. 15).
        np.testing.assert_allclose(mean, weights[k] @ model.component_means(queries[k]), rtol=1e-12)


@pytest.mark.parametrize("n_samples", [7, 700])  # one query's path; EM's (compiled, blocks)
def test_gaussian_log_pdf_matches_scipy(n_samples):
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(6)
    mixture = random_mixture(rng, 3, 4)
    x = rng.standard_normal((n_samples, 4))
    expected = np.stack(
        [
            multivariate_normal(m, c).logpdf(x)
            for m, c in zip(mixture["means"], mixture["covariances"])
        ],
        axis=1,
    )
    log_pdf = gaussian_log_pdf(x, mixture["means"], mixture["covariances"])
    np.testing.assert_allclose(log_pdf, expected, rtol=1e-12)


def test_bad_input_is_rejected():
    rng = np.random.default_rng(7)
    mixture = random_mixture(rng, 2, 3)
    with pytest.raises(ValueError, match="overlap"):
        Gmr(**mixture, input_dims=[0, 1], output_dims=[1, 2]).fit()
    with pytest.raises(ValueError, match="indices"):
        Gmr(**mixture, input_dims=[3]).fit()
    with pytest.raises(ValueError, match="covariances must have shape"):
        Gmr(**{**mixture, "covariances": mixture["covariances"][:, :2]}, input_dims=[0]).fit()
    model = Gmr(**mixture, input_dims=[0]).fit()
    with pytest.raises(ValueError, match="query must have shape"):
        model.predict(np.zeros(2))
    with pytest.raises(ValueError, match="NaN"):
        model.predict(np.array([np.nan]))
    with pytest.raises(ValueError, match=r"weights must have shape \(2,\) or \(1, 2\)"):
        model.predict(np.zeros(1), weights=np.ones(3) / 3)


def test_predictive_covariance_of_a_long_batch_agrees_with_the_gmr_package():
    # 100 queries: the per-component path of the log-density (64 or more samples).
    rng = np.random.default_rng(8)
    mixture = random_mixture(rng, 5, 4)
    inputs = np.array([0, 2])
    model = Gmr(**mixture, input_dims=inputs).fit()
    reference = gmr.GMM(n_components=5, random_state=0, **mixture)
    queries = rng.standard_normal((100, 2))
    means, covs = model.predict(queries)
    np.testing.assert_allclose(model.responsibilities(queries)[:3], [
        reference.condition(inputs, q).priors for q in queries[:3]], rtol=1e-8)
    for query, mean, cov in zip(queries, means, covs):
        collapsed = reference.condition(inputs, query).to_mvn()
        np.testing.assert_allclose(mean, collapsed.mean, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(cov, collapsed.covariance, rtol=1e-8, atol=1e-12)
    from scipy.stats import multivariate_normal

    x = rng.standard_normal((100, 4))
    expected = np.stack([multivariate_normal(m, c).logpdf(x)
                         for m, c in zip(mixture["means"], mixture["covariances"])], axis=1)
    np.testing.assert_allclose(gaussian_log_pdf(x, mixture["means"], mixture["covariances"]),
                               expected, rtol=1e-12)


def test_support_radius_conditions_on_the_input_clipped_onto_each_states_ellipsoid():
    # One state, input 1-D with sigma = 2, r = 3: a query 10 from the mean is clipped to 6
    # (by hand), so the output is mu^O + S^OI / S^II * 6, whatever the query beyond 6.
    covariance = np.array([[4.0, 1.0], [1.0, 2.0]])
    model = Gmr(priors=[1.0], means=[[1.0, -2.0]], covariances=[covariance], input_dims=[0],
                support_radius=3.0).fit()  # fmt: skip
    np.testing.assert_allclose(model.predict([11.0])[0], [-2.0 + 0.25 * 6.0], rtol=1e-12)
    np.testing.assert_allclose(model.predict([-99.0])[0], [-2.0 - 0.25 * 6.0], rtol=1e-12)
    np.testing.assert_allclose(model.predict([4.0])[0], [-2.0 + 0.25 * 3.0], rtol=1e-12)
    # Two states, 2-D input: inside a state's ellipsoid eq. 16; outside, eq. 16 at the point
    # of the ellipsoid on the ray from its mean (found by bisection on scipy's distance).
    from scipy.spatial.distance import mahalanobis

    rng = np.random.default_rng(3)
    mixture = random_mixture(rng, 2, 4)
    clipped = Gmr(**mixture, input_dims=[2, 0], support_radius=1.5).fit()
    plain = Gmr(**mixture, input_dims=[2, 0]).fit()
    for query in (mixture["means"][0][[2, 0]] + 0.1, rng.standard_normal(2) * 8.0):
        expected = []
        for mu, sigma in zip(mixture["means"], mixture["covariances"], strict=True):
            single = Gmr(priors=[1.0], means=[mu], covariances=[sigma], input_dims=[2, 0]).fit()
            inverse = np.linalg.inv(sigma[np.ix_([2, 0], [2, 0])])
            centre = mu[[2, 0]]
            point = query
            if mahalanobis(query, centre, inverse) > 1.5:
                low, high = 0.0, 1.0
                for _ in range(200):
                    middle = 0.5 * (low + high)
                    inside = mahalanobis(centre + middle * (query - centre), centre, inverse)
                    low, high = (middle, high) if inside < 1.5 else (low, middle)
                point = centre + low * (query - centre)
            expected.append(single.predict(point)[0])
        np.testing.assert_allclose(clipped.component_means(query), expected, rtol=1e-9)
    near = mixture["means"][0][[2, 0]] + 1e-3  # deep inside state 0's ellipsoid: eq. 16
    np.testing.assert_allclose(
        clipped.component_means(near)[0], plain.component_means(near)[0], rtol=1e-12
    )
    with pytest.raises(ValueError, match="support_radius"):
        Gmr(**mixture, input_dims=[0], support_radius=0.0).fit()
