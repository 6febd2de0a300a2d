// The one instantiation of Eigen's SVDs of Mat (see nonmin/svd.hpp).
#include "nonmin/svd.hpp"

template class Eigen::JacobiSVD<nonmin::Mat>;
template class Eigen::BDCSVD<nonmin::Mat>;
